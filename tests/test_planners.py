"""Top-grasp planners on synthetic views with known geometry: the paper's strategy."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.planning.grasp_geometry import (
    PadBand,
    back_face_is_flat,
    corridor,
    first_touched,
    pad_touch,
)
from pipeline.sim.hand_models import GRIPPERS
from pipeline.synthetic import box_object, cylinder_object, synthetic_observation
from pipeline.types import Bias, SymmetryInit, SymmetryPlane
from plugins.planners.top_parallel import TopParallel
from plugins.planners.top_three_finger import TopThreeFinger
from plugins.segmenters.table_cluster import TableCluster

PG70 = GRIPPERS["pg70"]
SDH = GRIPPERS["sdh"]


def _view(obj, yaw=0.0):
    observation = synthetic_observation(obj, (0.6, 0.0, yaw), rng=np.random.default_rng(8))
    # The paper's 20 mm cut, which the planners' own defaults assume.
    return TableCluster(TableCluster.Params(cut="fixed")).segment(observation)


def _true_plane(yaw=0.0):
    """Plane through the object centre (0.6, 0) with normal along the object's x axis."""
    normal = np.array([np.cos(yaw), np.sin(yaw)])
    return SymmetryInit(plane=SymmetryPlane(yaw, float(normal @ [0.6, 0.0])), bias=Bias())


def test_parallel_grasp_geometry_on_a_box_facing_the_camera():
    # Camera on the -x side; box 42 mm thick along x: front face at x = 0.579.
    cloud = _view(box_object(0.042, 0.15, 0.12))
    plan = TopParallel(TopParallel.Params(strategy="paper")).plan(cloud, _true_plane(), PG70)
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
    params = TopParallel.Params(strategy="paper", tactile_angle_deg=45.0)
    plan = TopParallel(params).plan(cloud, _true_plane(), PG70)
    angle = np.degrees(np.arctan2(plan.closing_direction[1], plan.closing_direction[0]))
    assert abs(angle) == pytest.approx(45.0, abs=1e-6)
    assert plan.closing_direction[0] > 0  # still from the camera side to the back


def test_parallel_pads_stay_above_the_table_for_a_short_object():
    cloud = _view(box_object(0.04, 0.1, 0.05))
    plan = TopParallel(TopParallel.Params(strategy="paper")).plan(cloud, _true_plane(), PG70)
    fingertip_z = plan.T_robot_hand[2, 3] - 0.125 - 0.029
    assert fingertip_z >= 0.01 - 1e-6


def test_parallel_refuses_a_too_wide_object():
    cloud = _view(box_object(0.09, 0.15, 0.12))
    plan = TopParallel(TopParallel.Params(strategy="paper")).plan(cloud, _true_plane(), PG70)
    assert plan.status == "refused"
    width_mm = float(plan.reason.split(" mm wide")[0].split()[-1])
    assert width_mm == pytest.approx(90.0, abs=3.0)
    assert "65.0 mm" in plan.reason


def _cylinder_front(axis_y=0.0, seed=0):
    """Visible points of a 26.5 mm cylinder on the axis (0.6, axis_y) inside a pad corridor
    along +x through (0.6, 0), and the corridor geometry."""
    observation = synthetic_observation(
        cylinder_object(0.0265, 0.13), (0.6, axis_y, 0.0), rng=np.random.default_rng(seed)
    )
    points = TableCluster().segment(observation).points
    band = PadBand(0.1, 0.0476, 0.0204)
    centre, direction = np.array([0.6, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    return points, corridor(points, centre, direction, band), centre, direction


@pytest.mark.parametrize("axis_y", [0.0, 0.004])
def test_pad_touch_finds_the_extreme_of_a_curved_face(axis_y):
    # The flat pad first touches the cylinder at x = 0.6 - r, on the line y = axis_y; the
    # median of the surface layer lies about w^2 / 6r = 0.65 mm behind (plus noise).
    points, mask, centre, direction = _cylinder_front(axis_y)
    median, _ = first_touched(points, mask, direction, 0.008)
    touch, touched = pad_touch(
        points,
        mask,
        centre,
        direction,
        band_m=0.008,
        half_width_m=0.0102,
        flat_radius_m=0.15,
        touch_depth_m=0.001,
    )
    front = 0.6 - 0.0265
    assert median - front > 0.0005
    assert touch == pytest.approx(front, abs=0.0004)
    assert touched[:, 1].mean() == pytest.approx(axis_y, abs=0.0015)
    np.testing.assert_allclose(touched @ direction, touch, atol=1e-12)


def test_pad_touch_on_a_turned_flat_face_is_its_position_on_the_closing_line():
    # A flat face turned 5 deg about z, depth noise 1.5 mm: the squeeze turns it flat
    # against the pad, so its position on the closing line (0.55, the layer's median) is
    # the touch, not its front edge 0.9 mm nearer.
    rng = np.random.default_rng(3)
    u = rng.uniform(-0.0102, 0.0102, 400)
    z = rng.uniform(0.08, 0.12, 400)
    depth = 0.55 + np.tan(np.deg2rad(5.0)) * u + rng.normal(0.0, 0.0015, 400)
    points = np.column_stack([depth, u, z])
    touch, touched = pad_touch(
        points,
        np.ones(400, dtype=bool),
        np.zeros(3),
        np.array([1.0, 0.0, 0.0]),
        band_m=0.008,
        half_width_m=0.0102,
        flat_radius_m=0.15,
        touch_depth_m=0.001,
    )
    assert touch == pytest.approx(0.55, abs=0.0004)
    assert len(touched) > 50


def test_parallel_pads_stay_above_the_cloud_bottom_on_a_short_object():
    # 50 mm tall box, cloud cut 20 mm above the table: a 47.6 mm pad covering the top would
    # reach below the cloud; it is raised so its lower edge stays above the cloud's bottom.
    cloud = _view(box_object(0.04, 0.1, 0.05))
    bottom = np.percentile(cloud.points[:, 2], 2.0)
    pad_bottom = {}
    for keep in (True, False):
        plan = TopParallel(TopParallel.Params(strategy="paper", pad_above_cloud=keep)).plan(
            cloud, _true_plane(), PG70
        )
        pad_bottom[keep] = plan.T_robot_hand[2, 3] - 0.125 - 0.0238
    assert pad_bottom[True] == pytest.approx(bottom, abs=1e-6)
    assert pad_bottom[False] < bottom - 0.004


def test_three_finger_grasp_on_a_cylinder():
    cloud = _view(cylinder_object(0.04, 0.15))
    plan = TopThreeFinger(TopThreeFinger.Params(strategy="paper")).plan(cloud, _true_plane(), SDH)
    assert plan.status == "ok"
    assert plan.spread_rad == pytest.approx(np.deg2rad(60.0))
    # Completed cloud centroid ~ axis (mirror through the true plane).
    np.testing.assert_allclose(plan.T_robot_hand[:2, 3], [0.6, 0.0], atol=0.004)
    np.testing.assert_allclose(plan.closing_direction, [1.0, 0.0, 0.0], atol=1e-9)
    # Contacts on the cylinder wall, one group per finger direction.
    radius = np.hypot(plan.predicted_contacts[:, 0] - 0.6, plan.predicted_contacts[:, 1])
    assert np.all(np.abs(radius - 0.04) < 0.01)


def test_three_finger_faces_the_thumb_on_a_flat_back():
    # Box 65 mm thick along x (back face at x = 0.6325), 130 mm long: fingers 1 and 2 at
    # spread 0 close along -x on lines 33 mm either side of the closing line.
    cloud = _view(box_object(0.065, 0.13, 0.15))
    plan = TopThreeFinger(TopThreeFinger.Params(strategy="paper")).plan(cloud, _true_plane(), SDH)
    assert plan.status == "ok" and plan.spread_rad == 0.0
    contacts = plan.predicted_contacts
    back = contacts[contacts[:, 0] > 0.6]
    assert np.abs(back[:, 0] - 0.6325).max() < 0.006
    for side in (1.0, -1.0):
        lateral = back[side * back[:, 1] > 0, 1] * side
        assert lateral.size > 0 and np.abs(lateral - 0.033).max() <= 0.0102 + 1e-9
    front = contacts[contacts[:, 0] < 0.6]
    assert np.abs(front[:, 0] - 0.5675).max() < 0.006 and np.abs(front[:, 1]).max() <= 0.0103


@pytest.mark.parametrize(
    ("obj", "flat"),
    [
        (box_object(0.065, 0.13, 0.15), True),
        (box_object(0.065, 0.05, 0.15), False),  # back narrower than the two fingers
        (cylinder_object(0.04, 0.15), False),
    ],
)
def test_back_face_is_flat_needs_a_wide_flat_back(obj, flat):
    visible = _view(obj).points
    completed = np.concatenate([visible, visible * [-1, 1, 1] + [1.2, 0.0, 0.0]])  # x = 0.6
    band = PadBand(0.12, 0.0442, 0.0204)
    result = back_face_is_flat(
        completed,
        np.array([1.0, 0.0, 0.0]),
        band,
        half_span_m=0.0432,
        band_m=0.008,
        flat_radius_m=0.15,
    )
    assert result is flat


def test_three_finger_pads_stay_above_the_cloud_bottom_on_a_low_object():
    # 60 mm tall: the segmented cloud starts 20 mm above the table; the table-clearance
    # bound alone would put the distal pad's (44.2 mm) lower edge at 15 mm, on surface that
    # no cloud point represents.
    cloud = _view(box_object(0.065, 0.13, 0.06))
    plan = TopThreeFinger(TopThreeFinger.Params(strategy="paper")).plan(cloud, _true_plane(), SDH)
    pad_bottom_z = plan.T_robot_hand[2, 3] - 0.21 - 13 * 0.0034 / 2
    assert pad_bottom_z >= np.percentile(cloud.points[:, 2], 2.0) - 1e-5
    assert pad_bottom_z >= 0.019


def test_three_finger_refuses_when_the_aperture_is_too_small():
    cloud = _view(cylinder_object(0.04, 0.15))
    small = dataclasses.replace(SDH, max_aperture_m=0.06)
    plan = TopThreeFinger(TopThreeFinger.Params(strategy="paper")).plan(cloud, _true_plane(), small)
    assert plan.status == "refused" and "60.0 mm" in plan.reason


def test_planners_check_the_number_of_fingers():
    cloud = _view(box_object(0.042, 0.15, 0.12))
    with pytest.raises(ConfigError, match="top-three-finger"):
        TopParallel(TopParallel.Params(strategy="paper")).plan(cloud, _true_plane(), SDH)
    with pytest.raises(ConfigError, match="top-parallel"):
        TopThreeFinger(TopThreeFinger.Params(strategy="paper")).plan(cloud, _true_plane(), PG70)


def test_parallel_reaches_down_to_a_low_object_only_when_nothing_else_is_feasible():
    # An 18 mm tall box segmented with the fitted cut (a few mm above the table), the table
    # taken at the cloud's bottom (the shipped config): with the fingertips 10 mm above it
    # the pads' lowest taxels stand over the box's top, so no grasp is feasible; reaching
    # down to 2 mm above the table the segmenter measured grasps it with both pads on its
    # sides, and without the measured table down to 2 mm above the lowest point seen.
    observation = synthetic_observation(
        box_object(0.04, 0.04, 0.018), (0.6, 0.0, 0.0), rng=np.random.default_rng(8)
    )
    cloud = TableCluster().segment(observation)
    bottom = float(cloud.points[:, 2].min())
    assert 0.002 < bottom < 0.008
    assert abs(cloud.table_height_m - observation.table_height_m) < 0.001
    plans = {}
    for low in (0.01, 0.002):
        params = TopParallel.Params(cloud_base_above_table_m=0.0, low_table_clearance_m=low)
        plans[low] = TopParallel(params).plan(cloud, _true_plane(), PG70)
    unmeasured = dataclasses.replace(cloud, table_height_m=None)
    plans[None] = TopParallel(params).plan(unmeasured, _true_plane(), PG70)
    assert plans[0.01].status == "refused"
    assert "no surface before the front pad" in plans[0.01].reason
    for plan, table in ((plans[0.002], cloud.table_height_m), (plans[None], bottom)):
        assert plan.status == "ok"
        fingertip_z = plan.T_robot_hand[2, 3] - 0.125 - 0.029
        assert fingertip_z == pytest.approx(table + 0.002, abs=1e-6)
        best = plan.candidates[0]
        assert len(best.contact_coverage) == 2 and min(best.contact_coverage) > 0.0
    # A tall box keeps the clearance: the lower reach is tried only when nothing else is.
    tall = TableCluster().segment(
        synthetic_observation(
            box_object(0.04, 0.1, 0.1), (0.6, 0.0, 0.0), rng=np.random.default_rng(8)
        )
    )
    low_heights = min(
        c.height_m
        for c in TopParallel(TopParallel.Params(cloud_base_above_table_m=0.0))
        .plan(tall, _true_plane(), PG70)
        .candidates
    )
    assert low_heights - 0.029 >= float(tall.points[:, 2].min()) + 0.01 - 1e-6
