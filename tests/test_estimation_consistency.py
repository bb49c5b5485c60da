"""Self-diagnosis: the consistency kernels against hand-computed cases, and the estimator's
verdicts on right and wrong synthetic problems."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from estimation_scenes import cylinder_scene, fusion_problem

from pipeline.estimation.after_view_term import AfterViewMeasurement
from pipeline.estimation.consistency import (
    ConsistencySettings,
    after_view_test,
    assess,
    free_space_count,
    normalised_innovations,
    pad_test,
    select_stage,
    surface_residuals,
    with_after_view_test,
)
from pipeline.estimation.covariances import normal_ellipsoids
from pipeline.estimation.iekf import GraspContacts
from pipeline.experiments.synthetic_study import make_estimator
from pipeline.metrics import diameter_error
from pipeline.perception.visibility import free_space_depths, visibility_violations
from pipeline.run.runner import run_estimator
from pipeline.synthetic import Cylinder, make_case
from pipeline.types import (
    Bias,
    CameraIntrinsics,
    Consistency,
    DepthObservation,
    Hypothesis,
    StageEstimate,
    SymmetryPlane,
)


def grid_plane(spacing_m: float = 0.002, half_m: float = 0.03) -> np.ndarray:
    """Points on the plane z = 0, a square grid."""
    steps = np.arange(-half_m, half_m + 1e-12, spacing_m)
    x, y = np.meshgrid(steps, steps)
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


def test_taxels_two_millimetres_off_a_plane_give_two_millimetres_rms_and_known_nis():
    taxels = grid_plane(0.0034, 0.01) + np.array([0.0005, 0.0003, 0.002])
    residuals = surface_residuals(taxels, grid_plane())
    assert residuals == pytest.approx(np.tile([0.0, 0.0, -0.002], (len(taxels), 1)), abs=1e-12)
    assert np.sqrt(np.mean(np.sum(residuals**2, axis=1))) == pytest.approx(0.002)
    # Along the taxel normal R has 1 mm std, the surface 2 mm: NIS = 2^2 / (1 + 4).
    noise = normal_ellipsoids(np.tile([0.0, 0.0, -1.0], (len(taxels), 1)), 0.001, 0.003)
    nis = normalised_innovations(residuals, noise, 0.002)
    assert nis == pytest.approx(np.full(len(taxels), 4.0 / 5.0))


def test_residual_to_a_curved_surface_is_the_radial_distance():
    angle = np.linspace(0.0, 2.0 * np.pi, 2000, endpoint=False)
    height = np.linspace(0.0, 0.1, 100)
    a, h = np.meshgrid(angle, height)
    cylinder = np.column_stack([0.04 * np.cos(a.ravel()), 0.04 * np.sin(a.ravel()), h.ravel()])
    taxels = np.array([[0.043, 0.0, 0.05], [0.0, -0.0385, 0.03]])
    distances = np.linalg.norm(surface_residuals(taxels, cylinder), axis=1)
    assert distances == pytest.approx([0.003, 0.0015], abs=1e-4)


def test_a_taxel_beyond_the_edge_of_the_model_is_measured_as_far_from_it():
    """A taxel in the plane of the model but 20 mm beyond its edge is not touching it."""
    taxel = np.array([[0.05, 0.0, 0.0]])
    distance = float(np.linalg.norm(surface_residuals(taxel, grid_plane())))
    assert 0.015 < distance <= 0.02


def test_pad_test_averages_within_pads_and_uses_chi_square_with_one_dof_per_pad():
    statistic, bound = pad_test(np.array([1.0, 1.0, 1.0, 3.0]), np.array(list("aaab")), 0.001)
    assert statistic == pytest.approx((1.0 + 3.0) / 2.0)
    # chi-square with 2 dof: the 1 - alpha quantile is -2 ln(alpha).
    assert bound == pytest.approx(-2.0 * math.log(0.001) / 2.0)
    assert pad_test(np.zeros(0), np.zeros(0), 0.001) == (
        pytest.approx(math.nan, nan_ok=True),
        math.inf,
    )


def test_free_space_tolerance_is_the_depth_difference_quantile():
    settings = ConsistencySettings(alpha=0.001, surface_std_m=0.002)
    # z_0.999 = 3.0902; the difference of two depths with 2 mm std each has 2.83 mm std.
    assert settings.free_space_tolerance_m == pytest.approx(
        3.0902 * math.sqrt(2.0) * 0.002, rel=1e-4
    )


def flat_view(depth_m: float = 1.0) -> DepthObservation:
    """A 40 x 30 camera at the robot origin looking along +x (optical z = robot x) at a wall
    ``depth_m`` away, with one NaN pixel."""
    intrinsics = CameraIntrinsics(width=40, height=30, fx=50.0, fy=50.0, cx=19.5, cy=14.5)
    depth = np.full((30, 40), depth_m, dtype=np.float32)
    depth[0, 0] = np.nan
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    rgb = np.zeros((30, 40, 3), dtype=np.uint8)
    return DepthObservation(depth_m=depth, rgb=rgb, intrinsics=intrinsics, T_robot_camera=T)


def test_free_space_depths_on_a_wall():
    view = flat_view()
    corner = [1.0, 19.5 / 50.0, 14.5 / 50.0]  # projects onto the NaN pixel (0, 0)
    points = np.array([[0.9, 0.0, 0.0], [1.1, 0.0, 0.0], [1.0, 5.0, 0.0], [-1.0, 0, 0], corner])
    depths = free_space_depths(points, view.depth_m, view.intrinsics, view.T_robot_camera)
    assert depths[:2] == pytest.approx([0.1, -0.1], abs=1e-6)
    assert np.all(np.isneginf(depths[2:]))
    assert free_space_count(depths, 0.05) == 1


def test_free_space_depths_agree_with_the_visibility_constraint_counts():
    view = flat_view()
    rng = np.random.default_rng(0)
    points = np.column_stack(
        [rng.uniform(0.95, 1.2, 400), rng.uniform(-0.2, 0.2, 400), rng.uniform(-0.1, 0.1, 400)]
    )
    plane = SymmetryPlane(theta_rad=0.3, offset_m=1.0)
    counts, _ = visibility_violations(
        points,
        np.array([plane.theta_rad]),
        np.array([plane.offset_m]),
        view.depth_m,
        view.intrinsics,
        view.T_robot_camera,
        tolerance_m=0.01,
    )
    depths = free_space_depths(
        plane.mirror(points), view.depth_m, view.intrinsics, view.T_robot_camera
    )
    assert 0 < counts[0] == free_space_count(depths, 0.01)


def test_assess_passes_the_true_state_and_fails_a_plane_thirty_millimetres_off():
    scene = cylinder_scene(4000)
    problem = fusion_problem(scene, scene.g_true)
    settings = ConsistencySettings()
    right = assess(
        scene.points_m, scene.g_true, [scene.g_true], scene.pivot_m, problem.grasps, None, settings
    )
    assert right.consistent and right.checks == ("taxels",)
    assert right.taxel_rms_m < 0.001 and right.free_space_violations is None
    wrong_g = scene.g_true + np.array([0, 0, 0, 0, 0.03, 0])
    wrong = assess(
        scene.points_m, wrong_g, [wrong_g], scene.pivot_m, problem.grasps, None, settings
    )
    assert not wrong.consistent and "taxels" in wrong.reason
    assert wrong.taxel_rms_m > 0.01 and wrong.excess > 1.0


def stage(
    index: int, excess_nis: float, violations: int | None = None, limit: int = 100
) -> StageEstimate:
    """A diagnosed stage whose taxel statistic is ``excess_nis`` of its bound (1) and, when
    ``violations`` is given, with that many points in seen free space against ``limit``."""
    camera = violations is not None
    passes = excess_nis <= 1.0 and (not camera or violations <= limit)
    verdict = Consistency(
        checks=("taxels", "free_space") if camera else ("taxels",),
        taxel_rms_m=0.001,
        nis=excess_nis,
        nis_threshold=1.0,
        free_space_violations=violations,
        free_space_limit=limit if camera else None,
        consistent=passes,
        reason="" if passes else "failed",
    )
    return StageEstimate(
        stage=index,
        plane=SymmetryPlane(0.0, 0.0),
        bias=Bias(),
        covariance=np.eye(6),
        points=np.zeros((1, 3)),
        completed=np.zeros((2, 3)),
        iterations=1,
        status="converged" if passes else "inconsistent",
        seconds=0.0,
        consistency=verdict,
    )


def test_selection_keeps_a_consistent_last_stage_and_otherwise_the_least_contradicted():
    assert select_stage([stage(0, 0.1), stage(1, 0.5), stage(2, 0.9)])[0] == 2
    assert select_stage([stage(0, 0.5), stage(1, 3.0), stage(2, 2.0)])[0] == 0
    index, reason = select_stage([stage(0, 9.0), stage(1, 1.5), stage(2, 2.0)])
    assert index == 1 and "Stage 1" in reason
    assert select_stage([stage(0, 9.0), stage(1, 3.0), stage(2, 2.0)])[0] == 2


def test_with_no_consistent_stage_the_camera_ranks_first():
    # Stage 0's taxels are far off (the object moved, or touched a part symmetry cannot
    # complete); the fused stages fit them by putting matter where the camera saw none.
    stages = [stage(0, 16.7, violations=15), stage(1, 0.1, 648), stage(2, 0.1, 645)]
    index, reason = select_stage(stages)
    assert index == 0 and "contradicts the camera" in reason
    # Among stages the camera accepts, the least contradicted by the taxels.
    stages = [stage(0, 16.7, violations=15), stage(1, 3.0, 20), stage(2, 0.1, 645)]
    assert select_stage(stages)[0] == 1
    # When the camera accepts none, the fewest points in seen free space for the limit.
    stages = [stage(0, 16.7, violations=150), stage(1, 3.0, 400), stage(2, 2.0, 120)]
    assert select_stage(stages)[0] == 2
    # ... even where the taxels contradict that stage more than the others' larger excess
    # (4.3 of the taxels' bound against 4.2 of the camera's: the pitcher's handle).
    stages = [stage(0, 4.3, violations=106), stage(1, 0.1, 425), stage(2, 0.1, 420)]
    index, reason = select_stage(stages)
    assert index == 0 and "fewest points in seen free space" in reason


def test_a_bounded_hypothesis_does_not_replace_a_consistent_stage_0():
    bounded = Hypothesis("held-angle, bounded", step=0.12, replaced="failed")
    last = dataclasses.replace(stage(2, 0.3), hypothesis=bounded)
    index, reason = select_stage([stage(0, 0.5), stage(1, 0.4), last])
    assert index == 0 and "12% of a 'held-angle, bounded' step" in reason
    # Stage 0 inconsistent: the bounded model is the one the evidence supports.
    assert select_stage([stage(0, 9.0), stage(1, 0.4), last])[0] == 2
    # A hypothesis taken in full (its own step passes) stands as any consistent stage.
    full = dataclasses.replace(last, hypothesis=Hypothesis("held-angle", replaced="failed"))
    assert select_stage([stage(0, 0.5), stage(1, 0.4), full])[0] == 2


def test_a_capped_stage_must_explain_the_taxels_clearly_better_than_a_consistent_stage_0():
    capped = dataclasses.replace(stage(2, 0.3), status="max_iterations")
    index, reason = select_stage([stage(0, 0.5), stage(1, 0.4), capped])
    assert index == 0 and "iteration cap" in reason and "0.30 vs 0.50" in reason
    # Half of Stage 0's misfit or less: the capped stage stands.
    assert select_stage([stage(0, 0.6), stage(1, 0.4), capped])[0] == 2
    # A converged stage needs no such margin, nor does a capped one over an inconsistent
    # Stage 0.
    assert select_stage([stage(0, 0.5), stage(1, 0.4), stage(2, 0.3)])[0] == 2
    assert select_stage([stage(0, 9.0), stage(1, 0.4), capped])[0] == 2


def grasp_with_view(motion: tuple[float, float, float] | None) -> GraspContacts:
    """One taxel; with ``motion`` an after-view that measured it with stds 0.01 rad and
    1 mm, 2 mm."""
    view = None
    if motion is not None:
        noise = np.diag([0.01**2, 0.001**2, 0.002**2])
        view = AfterViewMeasurement(np.array(motion), noise, gate=20.0, inliers=100)
    return GraspContacts(
        positions_m=np.zeros((1, 3)),
        pads=np.array(["left"]),
        window=np.eye(3)[None] * 1e-6,
        noise=np.eye(3)[None] * 1e-6,
        after_view=view,
    )


def test_the_after_view_test_weighs_the_bias_by_the_view_noise_with_three_dof_per_view():
    g = np.array([0.02, 0.003, -0.004, 0.001, 0.05, 0.3])
    # Yaw 1 std off, x 3 stds, y 1 std: 1 + 9 + 1; b_z and the plane are not measured.
    statistic, bound = after_view_test([grasp_with_view((0.03, 0.0, -0.002))], [g], 0.001)
    assert statistic == pytest.approx(11.0)
    assert bound == pytest.approx(16.2662, abs=1e-4)  # chi2.ppf(0.999, 3)
    # Two views: the statistics add, six degrees of freedom.
    grasps = [grasp_with_view((0.03, 0.0, -0.002)), grasp_with_view(None)]
    assert after_view_test(grasps, [g, g], 0.001)[0] == pytest.approx(11.0)
    twice = [grasp_with_view((0.03, 0.0, -0.002))] * 2
    statistic, bound = after_view_test(twice, [g, g], 0.01)
    assert statistic == pytest.approx(22.0) and bound == pytest.approx(16.8119, abs=1e-4)
    assert after_view_test([grasp_with_view(None)], [g], 0.001) is None


def test_a_fused_stage_whose_bias_the_after_view_contradicts_gives_way():
    grasps = [grasp_with_view((0.0, 0.005, 0.0))]  # the view saw the object move 5 mm

    def at(index: int, excess_nis: float, x_m: float, violations: int = 10) -> StageEstimate:
        g = np.array([0.0, x_m, 0.0, 0.0, 0.0, 0.0])
        moved = dataclasses.replace(stage(index, excess_nis, violations), grasp_g=(g,))
        return with_after_view_test(moved, grasps, 0.001)

    # Stage 0's bias is no estimate: not tested. The fused stages moved the object 1 mm
    # (4 stds from what the view saw, NIS 16 < 16.27) and 0.5 mm (4.5 stds, 20.25).
    initial, close, far = at(0, 0.5, 0.0), at(1, 0.2, 0.001), at(2, 0.1, 0.0005)
    assert initial.consistency.after_view_nis is None
    assert close.consistency.supported and not far.consistency.supported
    assert far.consistency.consistent and far.status == "converged"
    index, reason = select_stage([initial, close, far])
    assert index == 0 and "contradicts the after-view (NIS 20.3 > 16.3)" in reason
    # The supported stage that contradicts the evidence least: Stage 1 (0.98 of the
    # after-view's bound) over a Stage 0 at 0.99 of the taxels'.
    assert select_stage([at(0, 0.99, 0.0), close, far])[0] == 1
    # Stage 0 off the taxels (1.9 of the bound) still beats a stage the view puts six
    # times beyond its bound; the last fails the camera.
    off = at(0, 1.9, 0.0)
    slid = at(1, 0.3, -0.005)
    assert slid.consistency.excess > 6.0
    assert select_stage([off, slid, at(2, 0.1, 0.005, violations=200)])[0] == 0
    # A bias the view agrees with stands.
    assert select_stage([initial, close, at(2, 0.1, 0.0048)])[0] == 2


def test_a_last_stage_that_kept_its_prior_gives_way_to_the_last_that_did_not_fail():
    gave_up = dataclasses.replace(stage(2, 0.1), status="no_correspondence")
    index, reason = select_stage([stage(0, 0.5), stage(1, 0.2), gave_up])
    assert index == 1 and "Stage 2 ended no_correspondence" in reason
    initial = dataclasses.replace(stage(0, 0.5), status="initial")
    diverged = dataclasses.replace(stage(1, 0.1), status="diverged")
    assert select_stage([initial, diverged, dataclasses.replace(diverged, stage=2)])[0] == 0


def run_case(case, params=None, **overrides):
    problem = case.problem
    if overrides:
        problem = dataclasses.replace(problem, **overrides)
    return run_estimator(make_estimator("iekf", params or {}), problem)


def test_a_correct_fusion_is_converged_and_consistent_with_both_checks():
    case = make_case(np.random.default_rng(1), theta_error_rad=math.radians(45.0), r_error_m=0.02)
    result = run_case(case)
    final = result.final
    assert final.status == "converged"
    assert final.consistency.consistent
    assert final.consistency.checks == ("taxels", "free_space")
    assert result.selected_stage == 2
    assert abs(diameter_error(final.completed, case.cylinder.diameter_m)) < 0.004
    # Stage 0 (45 deg, 20 mm off) puts the mirrored back in front of the visible surface.
    initial = result.stage(0).consistency
    assert not initial.consistent and initial.free_space_violations > initial.free_space_limit


def test_contacts_of_a_larger_object_end_inconsistent():
    """Three pads touched the same cylinder scaled 1.4x: no plane and bias of the seen
    cylinder explains them."""
    case = make_case(np.random.default_rng(3), gripper="three_finger")
    big = make_case(
        np.random.default_rng(3),
        gripper="three_finger",
        cylinder=dataclasses.replace(Cylinder(), radius_m=1.4 * Cylinder().radius_m),
    )
    result = run_case(case, grasps=(big.contacts,))
    assert result.final.status == "inconsistent"
    assert not result.final.consistency.consistent


@pytest.mark.parametrize(
    ("gripper", "phi_deg", "theta_deg", "r_mm"),
    [("parallel", 0, 80, 40), ("parallel", 0, 67.5, 50)],
)
@pytest.mark.slow
def test_a_far_off_initial_plane_that_is_not_corrected_is_never_converged(
    gripper, phi_deg, theta_deg, r_mm
):
    case = make_case(
        np.random.default_rng(1),
        gripper=gripper,
        tactile_angle_rad=math.radians(phi_deg),
        theta_error_rad=math.radians(theta_deg),
        r_error_m=r_mm * 1e-3,
    )
    # Started at Stage 0, as in the paper, the filter stays far off and must say so.
    final = run_case(case, {"start_search": False}).final
    assert abs(diameter_error(final.completed, case.cylinder.diameter_m)) > 0.004
    assert final.status in ("inconsistent", "diverged", "no_correspondence")
    # Started where the coarse search puts it, it is corrected or says it is not.
    searched = run_case(case).final
    error = abs(diameter_error(searched.completed, case.cylinder.diameter_m))
    assert error < 0.004 or searched.status in ("inconsistent", "diverged", "no_correspondence")


@pytest.mark.slow
def test_a_far_off_start_that_one_pad_misled_is_corrected_without_it():
    """Three fingers, the plane 67.5 deg and 50 mm off: the plain fusion stays inconsistent,
    one pad alone contradicts Stage 0, and fused again without it the filter finds the
    cylinder, whose model then explains all three pads (pipeline.estimation.outlier_pads)."""
    case = make_case(
        np.random.default_rng(1),
        gripper="three_finger",
        tactile_angle_rad=math.radians(45.0),
        theta_error_rad=math.radians(67.5),
        r_error_m=0.05,
    )
    result = run_case(case)
    final = result.final
    assert final.hypothesis is not None and final.hypothesis.name.startswith("without ")
    assert final.hypothesis.replaced.startswith("taxels")
    assert abs(diameter_error(final.completed, case.cylinder.diameter_m)) < 0.004
    assert final.consistency.consistent and final.status in ("converged", "max_iterations")
    assert result.selected_stage == 2


def test_without_a_camera_image_only_the_taxels_are_checked():
    case = make_case(np.random.default_rng(1))
    result = run_case(case, view=None)
    for estimate in result.stages:
        assert estimate.consistency.checks == ("taxels",)
        assert estimate.consistency.free_space_violations is None
