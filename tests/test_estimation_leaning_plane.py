"""The estimator's state with a mirror plane of any orientation (seven parameters) against
independent oracles: finite differences, filterpy's EKF, the dense textbook reference, the
paper's six-parameter state where the plane is vertical, and a box on its edge whose
leaning plane the fusion recovers from a perturbed start."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from estimation_scenes import (
    frozen_measurement,
    fusion_problem,
    leaning_box_scene,
    one_step_and_filterpy,
    structured_and_dense,
)

from pipeline.estimation.consistency import ConsistencySettings, plane_turn_test
from pipeline.estimation.geometry import (
    apply_side,
    completed_model,
    invert_side,
    side_jacobian,
    side_linear_part,
    state_normal,
)
from pipeline.estimation.iekf import IekfSettings, fuse
from pipeline.estimation.measurement import linearise, predict
from pipeline.estimation.problem import (
    bias_plane_covariance,
    estimate_result,
    general_plane,
    plane_angle_stds,
    with_plane_turn_test,
)
from pipeline.io.formats import stage_to_json
from pipeline.run.runner import initial_estimate
from pipeline.types import Bias, Consistency, PointCloud, Symmetry, SymmetryInit, SymmetryPlane

RNG = np.random.default_rng(11)
G7 = np.array([0.3, 0.01, -0.02, 0.005, 0.013, 0.7, 0.6])
PIVOT = np.array([0.1, -0.05, 0.2])
PRIOR_STD = (0.05, 0.01, 0.01, 0.01, 0.0325, 0.17, 0.17)
#: The start's error: bias (rad, m), plane offset (m), azimuth and elevation (rad).
START_ERROR = np.array([-0.02, 0.002, 0.002, -0.001, 0.006, 0.08, -0.08])


@pytest.mark.parametrize("back", [False, True])
def test_general_side_jacobian_matches_central_differences(back):
    points = RNG.normal(0.0, 0.1, (5, 3))
    analytic = side_jacobian(points, G7, PIVOT, back)
    assert analytic.shape == (5, 3, 7)
    step = 1e-6
    for k in range(7):
        dg = np.zeros(7)
        dg[k] = step
        numeric = (
            apply_side(points, G7 + dg, PIVOT, back) - apply_side(points, G7 - dg, PIVOT, back)
        ) / (2 * step)
        np.testing.assert_allclose(analytic[:, :, k], numeric, atol=1e-8)


def test_general_mirror_is_an_involution_with_its_linear_part():
    points = RNG.normal(0.0, 0.1, (10, 3))
    normal = state_normal(G7)
    assert normal[2] == pytest.approx(np.sin(G7[6]))
    assert np.linalg.norm(normal) == pytest.approx(1.0)
    mirrored = apply_side(points, G7, PIVOT, back=True)
    np.testing.assert_allclose(invert_side(mirrored, G7, PIVOT, back=True), points, atol=1e-15)
    # The midpoint of a point and its (unbiased) mirror image lies on the plane.
    unbiased = invert_side(mirrored, G7, PIVOT, back=False)
    np.testing.assert_allclose(((points + unbiased) / 2) @ normal, G7[4], atol=1e-15)
    linear = side_linear_part(G7, back=True)
    np.testing.assert_allclose(np.linalg.det(linear), -1.0)
    np.testing.assert_allclose(
        mirrored - apply_side(np.zeros((1, 3)), G7, PIVOT, True), points @ linear.T, atol=1e-15
    )
    np.testing.assert_allclose(completed_model(points, G7, PIVOT)[10:], mirrored, atol=1e-15)


@pytest.mark.parametrize("back", [False, True])
def test_a_level_normal_is_the_papers_vertical_plane(back):
    points = RNG.normal(0.0, 0.1, (8, 3))
    g6 = G7[:6]
    g7 = np.array([*g6, 0.0])
    np.testing.assert_array_equal(
        apply_side(points, g7, PIVOT, back), apply_side(points, g6, PIVOT, back)
    )
    np.testing.assert_array_equal(
        completed_model(points, g7, PIVOT), completed_model(points, g6, PIVOT)
    )
    np.testing.assert_array_equal(
        side_jacobian(points, g7, PIVOT, back)[:, :, :6], side_jacobian(points, g6, PIVOT, back)
    )


@pytest.fixture(scope="module")
def box():
    # Few points keep the dense reference small; the oracles need no accuracy.
    return leaning_box_scene(120, np.radians(50.0), seed=4)


def _start(box):
    return box.g_true + START_ERROR


def _completed(g, points, pivot):
    return completed_model(points, g, pivot)


def test_leaning_stacked_jacobian_matches_central_differences(box):
    problem = fusion_problem(box, _start(box), prior_std=PRIOR_STD)
    measurement = frozen_measurement(problem, problem.g_init, box.points_m)
    assert measurement.back.any() and (~measurement.back).any()
    g, points = problem.g_init + 0.001, box.points_m + 1e-3
    lin = linearise(measurement, g, points, problem.pivot_m, with_points=True)
    assert lin.bias_plane_jacobian.shape[1] == 7
    step = 1e-7
    for k in range(7):
        dg = np.zeros(7)
        dg[k] = step
        numeric = (
            predict(measurement, g + dg, points, problem.pivot_m)
            - predict(measurement, g - dg, points, problem.pivot_m)
        ) / (2 * step)
        np.testing.assert_allclose(lin.bias_plane_jacobian[:, k], numeric, atol=1e-6)


def test_one_leaning_iteration_equals_filterpy_ekf_update(box):
    problem = fusion_problem(box, _start(box), prior_std=PRIOR_STD)
    ours, ours_covariance, ekf_state, ekf_covariance = one_step_and_filterpy(
        problem, problem.g_init, box.points_m
    )
    np.testing.assert_allclose(ours, ekf_state, atol=1e-10)
    np.testing.assert_allclose(ours_covariance, ekf_covariance, atol=1e-12)


def test_leaning_structured_and_dense_agree(box):
    problem = fusion_problem(box, _start(box), prior_std=PRIOR_STD, grasps=2)
    structured, dense = structured_and_dense(problem)
    for ours in structured:
        assert ours.covariance.shape == (7, 7)
    np.testing.assert_allclose(
        _completed(structured[1].g, structured[1].points, problem.pivot_m),
        _completed(dense[1].g, dense[1].points, problem.pivot_m),
        atol=1e-6,
    )


def _angle_deg(g_a, g_b):
    cosine = abs(float(state_normal(g_a) @ state_normal(g_b)))
    return float(np.degrees(np.arccos(min(cosine, 1.0))))


@pytest.mark.slow
@pytest.mark.parametrize("tilt_deg", [30.0, 55.0, 80.0])
def test_fusion_recovers_a_leaning_plane_from_a_perturbed_start(tilt_deg):
    # Dense as a camera sees a box (about 3 mm apart): on sparse points the weighted means
    # of the taxels' gates drift along the flat faces.
    box = leaning_box_scene(2000, np.radians(tilt_deg), seed=4)
    problem = fusion_problem(box, _start(box), prior_std=PRIOR_STD, facing=True)
    problem = dataclasses.replace(
        problem, covariance_init=bias_plane_covariance(PRIOR_STD, problem.g_init, box.pivot_m)
    )
    before = box.surface_distance(_completed(problem.g_init, box.points_m, box.pivot_m)).mean()
    assert _angle_deg(problem.g_init, box.g_true) > 4.0
    assert _offset_at_centre_m(problem.g_init, box) > 0.004
    assert before > 0.002
    for stage in fuse(problem, IekfSettings()):
        assert stage.status == "converged"
        assert _angle_deg(stage.g, box.g_true) < 1.5
        assert _offset_at_centre_m(stage.g, box) < 0.0015
        after = box.surface_distance(_completed(stage.g, stage.points, box.pivot_m)).mean()
        assert after < 0.5 * before
        assert np.all(np.linalg.eigvalsh(stage.covariance) > 0)
        assert np.all(np.diag(stage.covariance) < np.diag(problem.covariance_init))


def _offset_at_centre_m(g, box):
    """How far the plane of ``g`` passes from the box's centre (m), which the true plane
    contains (the unbiased frame)."""
    return abs(float(state_normal(g) @ box.centre_m) - g[4])


def test_a_leaning_plane_is_diagnosed_selected_and_reported(box):
    problem = fusion_problem(box, _start(box), prior_std=PRIOR_STD)
    outcomes = fuse(problem, IekfSettings(max_iterations=8))
    result = estimate_result(problem, outcomes, time.perf_counter(), None, ConsistencySettings())
    assert result.selected_stage is not None and result.selection_reason
    for stage, g in zip(result.stages, [problem.g_init, *(o.g for o in outcomes)], strict=True):
        assert stage.consistency is not None and stage.hypothesis is None
        assert stage.covariance.shape == (7, 7)
        symmetry = stage.symmetry
        assert symmetry.kind == "plane" and symmetry.covariance.shape == (3, 3)
        np.testing.assert_allclose(abs(symmetry.direction @ state_normal(g)), 1.0)
        values = symmetry.values  # (m_r, azimuth, elevation) of the upward normal
        assert values[2] == pytest.approx(abs(np.arcsin(state_normal(g)[2])))
        np.testing.assert_allclose(symmetry.covariance, stage.covariance[4:, 4:], atol=0.0)
        document = stage_to_json(stage)["symmetry"]
        assert document["kind"] == "plane"
        assert list(document["parameters"]) == ["m_r", "m_azimuth", "m_elevation"]
        assert np.array(document["covariance"]).shape == (3, 3)
        # A fused leaning plane's turn from Stage 0's is tested and written; Stage 0's not.
        turned = stage_to_json(stage)["consistency"].get("plane_turn_deg")
        assert ("plane_turn" in stage.consistency.checks) == (stage.stage > 0)
        assert (turned is None) == (stage.stage == 0)
        # The vertical stand-in shares the azimuth and the point nearest the origin.
        assert stage.plane.theta_rad == pytest.approx(g[5])
        assert stage.plane.offset_m == pytest.approx(g[4] * np.cos(g[6]))


def test_a_downward_normal_is_reported_by_its_upward_opposite():
    covariance = np.diag(np.square(PRIOR_STD))
    covariance[4, 6] = covariance[6, 4] = 1e-4
    downward = np.array([*G7[:6], -0.6])
    symmetry = general_plane(downward, covariance)
    m_r, azimuth, elevation = symmetry.values
    assert m_r == pytest.approx(-downward[4])
    assert elevation == pytest.approx(0.6)
    assert np.cos(azimuth - downward[5]) == pytest.approx(-1.0)
    flipped = covariance[4:, 4:] * np.array([[1, -1, 1], [-1, 1, -1], [1, -1, 1]])
    np.testing.assert_allclose(symmetry.covariance, flipped)
    assert general_plane(G7[:6], covariance[:6, :6]) is None


def test_stage_0_alone_of_a_leaning_plane_has_a_covariance_the_size_of_its_state(box):
    # `complete` without contacts reports Stage 0 alone (initial_estimate); a leaning
    # plane's state has seven parameters, so its unknown covariance must be 7 x 7 too.
    normal = state_normal(box.g_true)
    symmetry = Symmetry("plane", normal, box.g_true[4] * normal)
    init = SymmetryInit(
        plane=SymmetryPlane(theta_rad=0.0, offset_m=box.g_true[4]),
        bias=Bias(yaw_rad=0.0, translation_m=np.zeros(3), pivot_m=box.pivot_m),
        symmetry=symmetry,
    )
    stage = initial_estimate(PointCloud(points=box.points_m), init).stages[0]
    assert stage.covariance.shape == (7, 7) and np.isnan(stage.covariance).all()
    assert stage.symmetry.kind == "plane"
    np.testing.assert_allclose(abs(stage.symmetry.direction @ normal), 1.0)


def _normal_spread(g, stds):
    """Covariance of the unit normal (3 x 3) under the chart's angle stds, through
    central differences of :func:`state_normal` (not the analytic derivatives)."""
    step = 1e-6
    columns = []
    for k in (5, 6):
        dg = np.zeros(len(g))
        dg[k] = step
        columns.append((state_normal(g + dg) - state_normal(g - dg)) / (2 * step))
    jacobian = np.array(columns).T
    return jacobian @ np.diag(np.square(stds)) @ jacobian.T


@pytest.mark.parametrize("elevation", [0.0, 0.6, 1.3, -1.0])
def test_a_leaning_normal_may_turn_alike_in_every_direction(elevation):
    std = 0.05
    g = np.array([*G7[:6], elevation])
    spread = np.sort(np.linalg.eigvalsh(_normal_spread(g, plane_angle_stds(0.4, std, g))))
    # Both tangent directions of the sphere get the same variance; none along the normal.
    np.testing.assert_allclose(spread, [0.0, std**2, std**2], atol=1e-12)
    assert plane_angle_stds(0.4, std, G7[:6]) == (0.4,)


def test_at_the_charts_pole_the_azimuth_std_is_capped():
    std = 0.05
    g = np.array([*G7[:6], np.pi / 2 - 0.01])  # cos(elevation) = 0.01 < sin(std)
    azimuth_std, elevation_std = plane_angle_stds(0.4, std, g)
    assert elevation_std == std
    assert azimuth_std == pytest.approx(std / np.sin(std))
    spread = np.sort(np.linalg.eigvalsh(_normal_spread(g, (azimuth_std, elevation_std))))
    assert spread[2] == pytest.approx(std**2) and spread[1] < std**2


def _turn_prior(std):
    return np.diag(np.square([0.05, 0.01, 0.01, 0.002, 0.03, std / np.cos(G7[6]), std]))


def test_the_turn_test_measures_the_angle_between_normals():
    std, alpha = 0.05, 0.001
    # Chi-square with two degrees of freedom: its 1 - alpha quantile is -2 ln(alpha).
    bound = std * np.sqrt(-2.0 * np.log(alpha))
    for turn in (0.01, 0.2):
        g = np.array([*G7[:6], G7[6] + turn])  # along a meridian: the turn is the step
        measured, measured_bound = plane_turn_test(g, G7, _turn_prior(std), alpha)
        assert measured == pytest.approx(turn) and measured_bound == pytest.approx(bound)
    # The opposite normal is the same plane.
    opposite = np.array([*G7[:4], -G7[4], G7[5] + np.pi, -G7[6]])
    assert plane_turn_test(opposite, G7, _turn_prior(std), alpha)[0] == pytest.approx(0.0, abs=1e-7)


@pytest.mark.parametrize("turn", [0.05, 0.3])
def test_a_plane_turned_beyond_its_prior_is_inconsistent(turn):
    passed = Consistency(("taxels",), 0.001, 1.0, 5.0, None, None, True)
    fusion = dataclasses.make_dataclass("Fusion", ["g_init", "covariance_init"])(
        G7, _turn_prior(0.05)
    )
    g = np.array([*G7[:6], G7[6] + turn])
    verdict = with_plane_turn_test(passed, g, fusion, 0.001)
    assert verdict.checks == ("taxels", "plane_turn")
    assert verdict.plane_turn_deg == pytest.approx(np.degrees(turn))
    beyond = bool(turn > np.radians(verdict.plane_turn_bound_deg))
    assert verdict.consistent is not beyond
    assert (verdict.excess > 1.0) is beyond
    assert ("plane turned" in verdict.reason) is beyond
