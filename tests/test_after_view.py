"""The after-view: the planar registration, its composition with the camera's calibration
error, the hand mask, and the filter's use of it (no simulator: synthetic boxes)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.estimation.after_view_term import (
    AfterViewMeasurement,
    AfterViewSettings,
    after_view_measurement,
    compose,
)
from pipeline.estimation.iekf import fuse_after_view
from pipeline.estimation.registration import (
    RegistrationSettings,
    apply_planar,
    invert_planar,
    planar_residuals,
    register_planar,
)
from pipeline.estimation.structured import StructuredCovariance
from pipeline.perception.after_view import AfterViewCrop, hand_surface, split_points
from pipeline.types import (
    AfterView,
    Bias,
    CameraIntrinsics,
    Contacts,
    DepthObservation,
    EstimationProblem,
    PointCloud,
    SymmetryInit,
    SymmetryPlane,
)
from plugins.estimators.iekf import IekfEstimator

#: The box: across the plane (x), along it (y), height (m).
SIZE_M = np.array([0.06, 0.04, 0.10])
CENTRE_M = np.array([0.5, 0.1, 0.0])
PITCH_M = 0.0034


def box_front(rng: np.random.Generator, count: int, noise_m: float) -> np.ndarray:
    """Points on the faces a camera at -x, -y sees: x = -30 mm and y = -20 mm (frame R)."""
    half = SIZE_M / 2
    points = rng.uniform([-half[0], -half[1], 0.0], [half[0], half[1], SIZE_M[2]], (count, 3))
    on_side = rng.random(count) < 0.4
    points[~on_side, 0] = -half[0]
    points[on_side, 1] = -half[1]
    return points + CENTRE_M + rng.normal(0.0, noise_m, points.shape)


def jaw_contacts(shift_m: np.ndarray) -> Contacts:
    """Two pads of 3 x 4 taxels pressed on the faces x = +-30 mm of the box moved by
    ``shift_m``."""
    rows = (np.arange(3) - 1.0) * PITCH_M + SIZE_M[2] / 2
    cols = (np.arange(4) - 1.5) * PITCH_M
    col_grid, row_grid = np.meshgrid(cols, rows)
    positions, normals, pads = [], [], []
    for sign, pad in ((-1.0, "left"), (1.0, "right")):
        grid = np.column_stack(
            [
                np.full(row_grid.size, sign * SIZE_M[0] / 2),
                col_grid.ravel(),
                row_grid.ravel(),
            ]
        )
        positions.append(grid + CENTRE_M + shift_m)
        normals.append(np.tile([-sign, 0.0, 0.0], (row_grid.size, 1)))
        pads.append(np.full(row_grid.size, pad))
    positions = np.concatenate(positions)
    return Contacts(
        positions, np.concatenate(normals), np.concatenate(pads), np.arange(len(positions))
    )


def blank_view() -> DepthObservation:
    """A one-pixel observation from a camera at (-0.5, -0.5, 0.8): the after-view's
    points are given directly."""
    camera = np.eye(4)
    camera[:3, 3] = (-0.5, -0.5, 0.8)
    return DepthObservation(
        depth_m=np.full((1, 1), np.nan, dtype=np.float32),
        rgb=np.zeros((1, 1, 3), dtype=np.uint8),
        intrinsics=CameraIntrinsics(1, 1, 500.0, 500.0, 0.0, 0.0),
        T_robot_camera=camera,
    )


def test_planar_residual_jacobian_matches_finite_differences():
    rng = np.random.default_rng(3)
    first = box_front(rng, 50, 0.0)
    normals = rng.normal(size=(50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    observed = first + rng.normal(0.0, 0.003, first.shape)
    pivot = first.mean(axis=0)
    motion = np.array([0.07, 0.004, -0.006])
    _, jacobian = planar_residuals(observed, first, normals, motion, pivot)
    step = 1e-7
    for column in range(3):
        delta = np.zeros(3)
        delta[column] = step
        up, _ = planar_residuals(observed, first, normals, motion + delta, pivot)
        down, _ = planar_residuals(observed, first, normals, motion - delta, pivot)
        np.testing.assert_allclose(jacobian[:, column], (up - down) / (2 * step), atol=1e-7)


def test_compose_is_the_inverse_calibration_after_the_motion():
    rng = np.random.default_rng(4)
    points = rng.normal(size=(20, 3))
    pivot = np.array([0.3, -0.2, 0.1])
    motion, error = np.array([0.05, 0.01, -0.02]), np.array([-0.03, 0.004, 0.006])
    composed, by_motion, by_error = compose(motion, error)
    expected = invert_planar(apply_planar(points, motion, pivot), error, pivot)
    np.testing.assert_allclose(apply_planar(points, composed, pivot), expected, atol=1e-12)
    step = 1e-7
    for column in range(3):
        delta = np.zeros(3)
        delta[column] = step
        numeric = (compose(motion + delta, error)[0] - compose(motion - delta, error)[0]) / (
            2 * step
        )
        np.testing.assert_allclose(by_motion[:, column], numeric, atol=1e-7)
        numeric = (compose(motion, error + delta)[0] - compose(motion, error - delta)[0]) / (
            2 * step
        )
        np.testing.assert_allclose(by_error[:, column], numeric, atol=1e-7)


def test_registration_recovers_a_planar_motion_and_its_spread():
    rng = np.random.default_rng(5)
    first = box_front(rng, 3000, 0.001)
    pivot = first.mean(axis=0)
    errors = []
    for _ in range(4):
        truth = np.array([rng.normal(0.0, 0.02), *rng.normal(0.0, 0.006, 2)])
        observed = apply_planar(box_front(rng, 2500, 0.001), truth, pivot)
        registered = register_planar(observed, first, pivot)
        assert registered is not None and registered.converged
        errors.append((registered.motion - truth) / np.sqrt(np.diag(registered.covariance)))
    # The covariance is honest: errors within a few of its stds (not hundreds).
    assert np.max(np.abs(errors)) < 4.0


def test_registration_refuses_a_view_that_fixes_no_direction_along_the_face():
    rng = np.random.default_rng(6)
    face = rng.uniform([0.0, -0.02, 0.0], [0.0, 0.02, 0.1], (2000, 3))
    assert register_planar(face + np.array([0.001, 0.0, 0.0]), face, face.mean(axis=0)) is None
    # With a prior the free direction stays at the prior: the yaw and the slide along it.
    prior = np.diag([0.02**2, 0.005**2, 0.005**2])
    registered = register_planar(
        face + np.array([0.001, 0.0, 0.0]),
        face,
        face.mean(axis=0),
        normals=np.tile([1.0, 0.0, 0.0], (len(face), 1)),
        prior_covariance=prior,
    )
    assert registered.motion[1] == pytest.approx(0.001, abs=1e-4)
    assert np.sqrt(registered.covariance[2, 2]) == pytest.approx(0.005, rel=0.01)


def test_a_direction_only_a_few_edge_points_fix_keeps_its_prior():
    # A face seen face-on fixes the motion along its normal (x); across it only eight
    # grazing points on a fin's side face speak, and they sit 2 mm off (an edge's mixed
    # pixels).
    rng = np.random.default_rng(11)
    face = rng.uniform([0.0, -0.02, 0.0], [0.0, 0.02, 0.1], (2000, 3))
    side = rng.uniform([0.0, 0.03, 0.0], [0.01, 0.03, 0.1], (200, 3))
    first = np.vstack([face, side])
    normals = np.vstack([np.tile([1.0, 0.0, 0.0], (2000, 1)), np.tile([0.0, 1.0, 0.0], (200, 1))])
    shift = np.array([0.001, 0.0, 0.0])
    edge = side[:8] + shift + np.array([0.0, 0.002, 0.0])
    observed = np.vstack([face + shift + rng.normal(0.0, 0.001, face.shape), edge])
    prior = np.diag([0.02**2, 0.005**2, 0.005**2])
    pivot = face.mean(axis=0)

    def registered(points: float) -> np.ndarray:
        control = RegistrationSettings(min_leverage_points=points)
        moved = register_planar(observed, first, pivot, control, normals, prior)
        assert moved is not None and moved.converged
        return moved

    trusting, honest = registered(0.0), registered(10.0)
    # Counted as eight independent points the edge drags the slide by a millimetre and
    # claims it to under one.
    assert trusting.motion[2] > 8e-4
    assert np.sqrt(trusting.covariance[2, 2]) < 0.001
    # With less information than ten points' the direction keeps the prior.
    assert abs(honest.motion[2]) < 5e-4
    assert np.sqrt(honest.covariance[2, 2]) == pytest.approx(0.005, rel=0.02)
    assert honest.motion[1] == pytest.approx(shift[0], abs=1e-4)


def test_after_view_recovers_a_slide_along_the_plane_the_jaws_cannot_feel():
    # The jaws close across the plane (x) while the box slides 6 mm along it (y): the taxels
    # fix x, the after-view y.
    rng = np.random.default_rng(7)
    shift = np.array([0.002, 0.006, 0.0])
    cloud = PointCloud(box_front(rng, 800, 0.001))
    after = box_front(rng, 600, 0.001) + shift
    init = SymmetryInit(plane=SymmetryPlane(0.0, CENTRE_M[0] + 0.004), bias=Bias())
    problem = EstimationProblem(
        cloud, init, (jaw_contacts(shift),), after_views=(AfterView(blank_view(), after),)
    )
    # A camera calibrated to 1 mm: the after-view then says where the object went.
    calibrated = {"after_view_calibration_xy_m": 0.001, "after_view_calibration_yaw_rad": 0.005}
    seen = IekfEstimator(calibrated).estimate(problem).stage(2).bias
    blind = IekfEstimator({**calibrated, "after_view": False}).estimate(problem).stage(2).bias
    seen_along = seen.translation_m[1] + 0.0
    assert abs(seen_along - shift[1]) < 0.0015
    assert abs(seen.translation_m[0] - shift[0]) < 0.0015
    # Without it the slide stays unknown: the test can fail.
    assert abs(blind.translation_m[1] - shift[1]) > 0.003


def test_after_view_update_is_the_kalman_update_and_gates_outliers():
    rng = np.random.default_rng(8)
    factor = rng.normal(size=(6, 6))
    prior = factor @ factor.T * 1e-4 + np.eye(6) * 1e-5
    g = rng.normal(0.0, 0.01, 6)
    noise = np.diag([1e-4, 4e-6, 9e-6])
    moved = g[:3] + np.array([0.002, 0.001, -0.001])
    measured = AfterViewMeasurement(moved, noise, gate=16.27, inliers=100)
    covariance = StructuredCovariance(prior, np.zeros(0))
    updated, _ = fuse_after_view((covariance,), None, g, np.zeros((0, 3)), measured, False)
    h = np.eye(6)[:3]
    gain = prior @ h.T @ np.linalg.inv(h @ prior @ h.T + noise)
    np.testing.assert_allclose(updated, g + gain @ (measured.motion - g[:3]), atol=1e-12)
    np.testing.assert_allclose(covariance.bias_plane(), (np.eye(6) - gain @ h) @ prior, atol=1e-12)
    far = AfterViewMeasurement(g[:3] + np.array([1.0, 0.5, 0.5]), noise, gate=16.27, inliers=100)
    kept = StructuredCovariance(prior, np.zeros(0))
    unchanged, _ = fuse_after_view((kept,), None, g, np.zeros((0, 3)), far, False)
    np.testing.assert_array_equal(unchanged, g)
    np.testing.assert_array_equal(kept.bias_plane(), prior)


def finger_meshes() -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Two 20 x 10 x 60 mm finger boxes pressing the box's x faces (the hand)."""
    import trimesh

    meshes = {}
    for sign, name in ((-1.0, "left"), (1.0, "right")):
        finger = trimesh.creation.box(extents=(0.01, 0.02, 0.06))
        finger.apply_translation(CENTRE_M + np.array([sign * (SIZE_M[0] / 2 + 0.005), 0.0, 0.06]))
        meshes[name] = (finger.vertices, finger.faces, finger.vertex_normals)
    return meshes


def test_hand_mask_keeps_the_object_outside_the_hand_and_no_hand_point():
    rng = np.random.default_rng(9)
    crop = AfterViewCrop()
    hand, normals = hand_surface(finger_meshes(), crop.hand_spacing_m)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    # The camera sees the hand's surface off by up to a calibration error of 5 mm and noise.
    seen_hand = hand[rng.choice(len(hand), 3000)] + np.array([0.004, -0.003, 0.0])
    seen_hand += rng.normal(0.0, 0.001, seen_hand.shape).clip(-0.003, 0.003)
    seen_object = box_front(rng, 4000, 0.001)
    points = np.vstack([seen_object, seen_hand])
    first = box_front(rng, 3000, 0.001)
    visible, on_hand = split_points(points, first, 0.0, hand, crop)
    from scipy.spatial import cKDTree

    hand_tree = cKDTree(hand)
    # No hand point is left among the object's.
    assert not np.isin(visible, seen_hand).all(axis=1).any()
    # Every object point outside the hand's footprint (its margin) is kept ...
    outside = hand_tree.query(seen_object)[0] > crop.hand_margin_m
    above = seen_object[:, 2] > crop.table_clearance_m
    kept = np.isin(seen_object, visible).all(axis=1)
    assert kept[outside & above].all()
    # ... and the hand's points are what the mask took out.
    assert np.isin(seen_hand, on_hand).all(axis=1).all()


def test_a_hand_in_view_measures_the_calibration_error_it_constrains():
    # The camera's calibration error moves the hand's points as it moves the object's: the
    # registration of the hand gives it, and the measurement is the motion without it.
    rng = np.random.default_rng(10)
    crop = AfterViewCrop()
    hand, normals = hand_surface(finger_meshes(), crop.hand_spacing_m)
    pivot = CENTRE_M + np.array([0.0, 0.0, 0.05])
    error = np.array([0.0, 0.0, 0.003])
    camera = blank_view().T_robot_camera[:3, 3]
    facing = np.einsum("ij,ij->i", normals, camera - hand) > 0.0
    seen_hand = apply_planar(hand[facing][rng.choice(facing.sum(), 3000)], error, pivot)
    seen_hand += rng.normal(0.0, 0.0005, seen_hand.shape)
    first = box_front(rng, 3000, 0.0005)
    shift = np.array([0.0, 0.002, 0.0])
    after = apply_planar(box_front(rng, 2500, 0.0005) + shift, error, pivot)
    view = AfterView(blank_view(), after, seen_hand, hand, normals)
    measured = after_view_measurement(view, first, pivot, AfterViewSettings(hand_calibration=True))
    # The fingers' faces turned to the camera fix the error along x and y.
    np.testing.assert_allclose(measured.motion[1:], shift[:2], atol=5e-4)
    # Without the hand the measurement is the motion the camera saw, error and all.
    blind = after_view_measurement(
        AfterView(blank_view(), after), first, pivot, AfterViewSettings()
    )
    assert abs(blind.motion[2] - shift[1]) > 2e-3


#: A trial's recorded files ``fuse`` reads: option, file.
RECORDED = (("cloud", "cloud.ply"), ("contacts", "contacts.json"), ("depth", "depth.npy"))


@pytest.mark.slow
def test_fuse_with_the_after_depth_repeats_the_trial(tmp_path):
    from pipeline.cli import main

    trial = tmp_path / "trial"
    argv = ["trial", "--object", "spray_bottle", "--init", "ps", "--out", str(trial)]
    assert main([*argv, "--set", "trial.pictures=false"]) in (0, 3)
    contacts = json.loads((trial / "contacts.json").read_text())
    assert contacts["grasps"][0]["after_depth"] == "after_depth.npy"
    assert (trial / "after_depth.npy").exists()

    def fuse(name: str, *extra: str) -> list:
        recorded = [f"--{kind}={trial / file}" for kind, file in RECORDED]
        code = main(["fuse", *recorded, "--init", "ps", *extra, "--out", str(tmp_path / name)])
        assert code in (0, 3)
        return json.loads((tmp_path / name / "result.json").read_text())["stages"]

    fused = [fuse("from-contacts"), fuse("given", f"--after-depth={trial / 'after_depth.npy'}")]
    expected = json.loads((trial / "result.json").read_text())["stages"]
    for stages in fused:
        for stage, mine in zip(expected, stages, strict=True):
            assert mine["bias"]["translation"] == pytest.approx(
                stage["bias"]["translation"], abs=1e-9
            )
            assert mine["plane"]["offset"] == pytest.approx(stage["plane"]["offset"], abs=1e-9)
    # Without the after-view the same recording fuses otherwise: the view counted.
    stages = fuse("blind", "--set", "estimator.iekf.after_view=false")
    assert stages[1]["bias"]["translation"] != pytest.approx(
        expected[1]["bias"]["translation"], abs=1e-6
    )


def test_fuse_refuses_an_after_view_it_cannot_use(recording, tmp_path, run):
    folder, _, plane = recording
    np.save(tmp_path / "after.npy", np.full((4, 4), np.nan, dtype=np.float32))
    base = ["fuse", "--cloud", folder / "cloud.ply", f"--plane={plane}"]
    code, _, err = run(
        *base,
        "--contacts",
        folder / "contacts.json",
        "--after-camera",
        tmp_path / "c.json",
        "--out",
        tmp_path / "none",
    )
    assert code == 2
    assert err.startswith("symfuse: error: --after-camera describes the camera of --after-depth")
    # The recording has no hand pose: the hand could not be masked out of the view.
    code, _, err = run(
        *base,
        "--contacts",
        folder / "contacts.json",
        "--after-depth",
        tmp_path / "after.npy",
        "--out",
        tmp_path / "out",
    )
    assert code != 0
    assert err.count("\n") == 1
    assert "grasp 1's after-view needs the grasp's 'plan' and 'hand'" in err
    document = json.loads((folder / "contacts.json").read_text())
    document["grasps"][0]["after_depth"] = 7
    (tmp_path / "bad.json").write_text(json.dumps(document))
    code, _, err = run(*base, "--contacts", tmp_path / "bad.json", "--out", tmp_path / "out2")
    assert code != 0
    assert "grasps[0].after_depth must be a file name" in err
