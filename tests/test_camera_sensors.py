"""The simulated sensor sources in the pybullet world: geometry, masks, calibration error."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from pipeline.errors import ConfigError
from pipeline.params import build
from pipeline.types import GraspPlan
from plugins.sensors.pybullet_kinect import PybulletKinect
from plugins.sensors.pybullet_stereo import PybulletStereo
from plugins.worlds.pybullet_world import Pybullet

BOX_SIZE_M = (0.06, 0.15, 0.2)
BOX_AT = (0.5, 0.05, 0.3)  # x, y (m), yaw (rad)


def box_object():
    mesh = trimesh.creation.box(BOX_SIZE_M)
    mesh.apply_translation((0.0, 0.0, BOX_SIZE_M[2] / 2))
    return SimpleNamespace(name="box", mesh=mesh, mass_kg=0.4, friction=0.6)


@pytest.fixture(scope="module")
def world():
    x, y, yaw = BOX_AT
    with Pybullet.create(box_object(), None, x=x, y=y, yaw=yaw, seed=3) as world:
        yield world


def back_project(observation, mask):
    rows, cols = np.nonzero(mask & np.isfinite(observation.depth_m))
    k = observation.intrinsics
    z = observation.depth_m[rows, cols].astype(np.float64)
    points_camera = np.stack([(cols - k.cx) * z / k.fx, (rows - k.cy) * z / k.fy, z], axis=1)
    T = observation.T_robot_camera
    return points_camera @ T[:3, :3].T + T[:3, 3]


def distance_to_box_m(points_robot):
    """Unsigned distance from robot-frame points to the true box's surface."""
    x, y, yaw = BOX_AT
    c, s = np.cos(yaw), np.sin(yaw)
    local = points_robot - [x, y, BOX_SIZE_M[2] / 2]
    local[:, :2] = local[:, :2] @ np.array([[c, -s], [s, c]])
    half = np.array(BOX_SIZE_M) / 2
    outside = np.linalg.norm(np.maximum(np.abs(local) - half, 0.0), axis=1)
    inside = np.min(half - np.abs(local), axis=1)
    return np.where(outside > 0, outside, np.maximum(inside, 0.0))


def test_world_places_the_object_and_refuses_grasps_without_a_hand(world):
    pose = world.object_pose()
    np.testing.assert_allclose(pose.position_m, [BOX_AT[0], BOX_AT[1], 0.0], atol=5e-4)
    assert world.gripper is None and world.sim.hand is None
    plan = GraspPlan("pg70", "ok", np.eye(4), 0.1, 0.065, np.array([1.0, 0.0, 0.0]))
    with pytest.raises(ConfigError, match="has no hand"):
        world.execute_grasp(plan)


def test_noise_free_kinect_points_lie_on_the_box(world):
    sensor = PybulletKinect(build(PybulletKinect.Params, {"noise": False}, "sensor"))
    observation = sensor.observe(world)
    assert observation.depth_m.shape == (480, 640) and observation.depth_m.dtype == np.float32
    assert observation.rgb.shape == (480, 640, 3)
    assert observation.table_height_m == world.table_height_m
    points = back_project(observation, observation.object_mask)
    assert len(points) > 3000
    assert np.max(distance_to_box_m(points)) < 1e-3


def test_noisy_kinect_matches_the_box_within_its_noise_and_drops_edges(world):
    observation = PybulletKinect().observe(world)
    clean = PybulletKinect(build(PybulletKinect.Params, {"noise": False}, "sensor"))
    truth = clean.observe(world)
    points = back_project(observation, observation.object_mask)
    assert np.median(distance_to_box_m(points)) < 2e-3
    # Pixels that saw the box in both images: error std as Nguyen et al. predict for
    # their depths (every box face is seen at 40-60 deg here, below the grazing term).
    both = truth.object_mask & observation.object_mask & np.isfinite(observation.depth_m)
    z = truth.depth_m[both].astype(np.float64)
    error = observation.depth_m[both] - z
    nguyen_sigma = np.sqrt(np.mean((0.0012 + 0.0019 * (z - 0.4) ** 2) ** 2))
    assert np.std(error) == pytest.approx(nguyen_sigma, rel=0.25)
    missing = ~np.isfinite(observation.depth_m)
    mask = observation.object_mask
    assert 0.0 < missing[mask].mean() < 0.3  # edges and shadows lose some object pixels
    assert np.isfinite(truth.depth_m[truth.object_mask]).all()


def test_sensor_noise_is_reproducible_from_the_world_seed():
    x, y, yaw = BOX_AT
    depths = []
    for _ in range(2):
        with Pybullet.create(box_object(), None, x=x, y=y, yaw=yaw, seed=9) as world:
            depths.append(PybulletKinect().observe(world).depth_m)
    np.testing.assert_array_equal(depths[0], depths[1])


def test_calibration_error_moves_the_cloud_by_a_planar_motion_about_the_target(world):
    values = {"noise": False}
    with_error = {**values, "calibration_yaw_deg": 2.0, "calibration_translation_m": [0.01, 0, 0]}
    true = PybulletKinect(build(PybulletKinect.Params, values, "sensor")).observe(world)
    wrong = PybulletKinect(build(PybulletKinect.Params, with_error, "sensor")).observe(world)
    np.testing.assert_array_equal(true.depth_m, wrong.depth_m)
    points_true = back_project(true, true.object_mask)
    points_wrong = back_project(wrong, wrong.object_mask)
    # The default target: 5 cm above the object where it rests, a fraction of a
    # micrometre from where it was put.
    pivot = world.object_pose().position_m + np.array([0.0, 0.0, 0.05])
    yaw = np.deg2rad(2.0)
    c, s = np.cos(yaw), np.sin(yaw)
    rotation = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    expected = (points_true - pivot) @ rotation.T + pivot + [0.01, 0.0, 0.0]
    np.testing.assert_allclose(points_wrong, expected, atol=2e-4)
    # The observation states that motion, for scoring the estimated bias.
    np.testing.assert_allclose(true.calibration_error, np.eye(4), atol=1e-12)
    error = wrong.calibration_error
    np.testing.assert_allclose(points_true @ error[:3, :3].T + error[:3, 3], expected, atol=1e-9)


def test_stereo_sees_the_box_with_z_squared_noise(world):
    clean = PybulletStereo(build(PybulletStereo.Params, {"noise": False}, "sensor"))
    truth = clean.observe(world)
    noisy = PybulletStereo().observe(world)
    both = truth.object_mask & np.isfinite(noisy.depth_m) & np.isfinite(truth.depth_m)
    assert both.sum() > 10_000  # f = 1600 px: the box fills much of the image
    error = (noisy.depth_m - truth.depth_m)[both].astype(np.float64)
    z = truth.depth_m[both].astype(np.float64)
    expected_sigma = np.sqrt(np.mean(z**4)) * 0.2 / (1600.0 * 0.09)
    assert np.std(error) == pytest.approx(expected_sigma, rel=0.2)
    assert np.max(distance_to_box_m(back_project(truth, truth.object_mask))) < 1e-3


def test_camera_params_are_validated():
    with pytest.raises(ConfigError, match=r"sensor\.pybullet-stereo\.target_m': expected 3"):
        PybulletStereo(build(PybulletStereo.Params, {"target_m": [0.0, 0.1]}, "sensor"))
    with pytest.raises(ConfigError, match="distance_m"):
        build(PybulletKinect.Params, {"distance_m": -1.0}, "sensor")


def test_world_loads_the_named_hand_when_available():
    hands = pytest.importorskip("pipeline.sim.hands")
    x, y, yaw = BOX_AT
    with Pybullet.create(box_object(), "pg70", x=x, y=y, yaw=yaw, seed=0) as world:
        assert isinstance(world.sim.hand, hands.Hand)
        assert world.gripper == world.sim.hand.spec
        np.testing.assert_allclose(world.object_pose().position_m[:2], [x, y], atol=1e-3)
