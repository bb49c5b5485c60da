"""Top-grasp planners on synthetic views with known geometry."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.perception.synthetic import box_object, cylinder_object, synthetic_observation
from pipeline.types import Bias, GripperSpec, PadLayout, SymmetryInit, SymmetryPlane
from plugins.table_cluster import TableCluster
from plugins.top_parallel import TopParallel
from plugins.top_three_finger import TopThreeFinger

PG70 = GripperSpec(
    "pg70",
    2,
    0.065,
    tuple(PadLayout(s, f"{s}_pad", 14, 6, 0.0034) for s in ("left", "right")),
    0.154,
)
SDH = GripperSpec(
    "sdh",
    3,
    0.2196,
    tuple(
        PadLayout(f"{f}_{link}", f"{f}_{link}_pad", rows, 6, 0.0034)
        for f in ("f1", "f2", "thumb")
        for link, rows in (("proximal", 14), ("distal", 13))
    ),
    0.246,
)


def _view(obj, yaw=0.0):
    observation = synthetic_observation(obj, (0.6, 0.0, yaw), rng=np.random.default_rng(8))
    return TableCluster().segment(observation)


def _true_plane(yaw=0.0):
    """Plane through the object centre (0.6, 0) with normal along the object's x axis."""
    normal = np.array([np.cos(yaw), np.sin(yaw)])
    return SymmetryInit(plane=SymmetryPlane(yaw, float(normal @ [0.6, 0.0])), bias=Bias())


def test_parallel_grasp_geometry_on_a_box_facing_the_camera():
    # Camera on the -x side; box 42 mm thick along x: front face at x = 0.579.
    cloud = _view(box_object(0.042, 0.15, 0.12))
    plan = TopParallel().plan(cloud, _true_plane(), PG70)
    assert plan.status == "ok"
    np.testing.assert_allclose(plan.closing_direction, [1.0, 0.0, 0.0], atol=1e-9)
    T = plan.T_robot_hand
    np.testing.assert_allclose(T[:3, 2], [0.0, 0.0, -1.0])
    np.testing.assert_allclose(T[:3, 0], plan.closing_direction)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    # Front pad 10 mm before the face, opened to 65 mm: palm centre at 0.569 + 0.0325.
    assert T[0, 3] == pytest.approx(0.579 - 0.010 + 0.0325, abs=0.0015)
    assert T[1, 3] == pytest.approx(0.0, abs=0.002)
    # Pad (47.6 mm) top edge 5 mm below the 120 mm top; palm 125 mm above the pad centre.
    assert T[2, 3] == pytest.approx(0.12 - 0.005 - 0.0238 + 0.125, abs=0.004)
    assert plan.opening_m == 0.065
    contacts = plan.predicted_contacts
    assert len(contacts) > 10
    assert np.abs(contacts[:, 0] - 0.579).max() < 0.01
    assert np.abs(contacts[:, 1]).max() <= 0.0102 + 1e-9


def test_parallel_tactile_angle_rotates_the_closing_direction():
    cloud = _view(box_object(0.042, 0.042, 0.12))
    params = TopParallel.Params(tactile_angle_deg=45.0)
    plan = TopParallel(params).plan(cloud, _true_plane(), PG70)
    angle = np.degrees(np.arctan2(plan.closing_direction[1], plan.closing_direction[0]))
    assert abs(angle) == pytest.approx(45.0, abs=1e-6)
    assert plan.closing_direction[0] > 0  # still from the camera side to the back


def test_parallel_pads_stay_above_the_table_for_a_short_object():
    cloud = _view(box_object(0.04, 0.1, 0.05))
    plan = TopParallel().plan(cloud, _true_plane(), PG70)
    fingertip_z = plan.T_robot_hand[2, 3] - 0.125 - 0.029
    assert fingertip_z >= 0.01 - 1e-6


def test_parallel_refuses_a_too_wide_object():
    cloud = _view(box_object(0.09, 0.15, 0.12))
    plan = TopParallel().plan(cloud, _true_plane(), PG70)
    assert plan.status == "refused"
    width_mm = float(plan.reason.split(" mm wide")[0].split()[-1])
    assert width_mm == pytest.approx(90.0, abs=3.0)
    assert "65.0 mm" in plan.reason


def test_three_finger_grasp_on_a_cylinder():
    cloud = _view(cylinder_object(0.04, 0.15))
    plan = TopThreeFinger().plan(cloud, _true_plane(), SDH)
    assert plan.status == "ok"
    assert plan.spread_rad == pytest.approx(np.deg2rad(60.0))
    # Completed cloud centroid ~ axis (mirror through the true plane).
    np.testing.assert_allclose(plan.T_robot_hand[:2, 3], [0.6, 0.0], atol=0.004)
    np.testing.assert_allclose(plan.closing_direction, [1.0, 0.0, 0.0], atol=1e-9)
    # Contacts on the cylinder wall, one group per finger direction.
    radius = np.hypot(plan.predicted_contacts[:, 0] - 0.6, plan.predicted_contacts[:, 1])
    assert np.all(np.abs(radius - 0.04) < 0.01)


def test_three_finger_refuses_when_the_aperture_is_too_small():
    cloud = _view(cylinder_object(0.04, 0.15))
    small = GripperSpec("sdh", 3, 0.06, SDH.pads, 0.246)
    plan = TopThreeFinger().plan(cloud, _true_plane(), small)
    assert plan.status == "refused" and "60.0 mm" in plan.reason


def test_planners_check_the_number_of_fingers():
    cloud = _view(box_object(0.042, 0.15, 0.12))
    with pytest.raises(ConfigError, match="top-three-finger"):
        TopParallel().plan(cloud, _true_plane(), SDH)
    with pytest.raises(ConfigError, match="top-parallel"):
        TopThreeFinger().plan(cloud, _true_plane(), PG70)
