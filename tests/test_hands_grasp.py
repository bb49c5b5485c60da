"""The PyBullet hands and grasp execution, checked against yourdfpy kinematics, the
datasheet geometry and the physics of simple objects."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pybullet as pb
import pytest
import yourdfpy

from pipeline.errors import ConfigError
from pipeline.geometry.pad_layout import pad_grid
from pipeline.planning import sdh_geometry
from pipeline.sim.grasping import (
    HAND_GRASP_SETTINGS,
    execute_grasp,
    object_pose,
    opposed_fingers,
    release,
)
from pipeline.sim.hands import GRIPPERS, Hand
from pipeline.types import GraspPlan
from robots import ROOT

MM = 1e-3
TOP_DOWN = np.diag([1.0, -1.0, -1.0])

SDH = sdh_geometry.shipped()  # the SDH-2's kinematics, read from its URDF


@pytest.fixture
def client() -> Iterator[int]:
    client = pb.connect(pb.DIRECT)
    pb.setGravity(0, 0, -9.81, physicsClientId=client)
    plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
    pb.createMultiBody(0, plane, physicsClientId=client)
    yield client
    pb.disconnect(client)


def _box(client: int, half_extents, position) -> int:
    shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half_extents, physicsClientId=client)
    body = pb.createMultiBody(0.2, shape, basePosition=position, physicsClientId=client)
    pb.changeDynamics(body, -1, lateralFriction=0.5, physicsClientId=client)
    return body


def _cylinder(client: int, radius: float, height: float, position) -> int:
    shape = pb.createCollisionShape(
        pb.GEOM_CYLINDER, radius=radius, height=height, physicsClientId=client
    )
    body = pb.createMultiBody(0.2, shape, basePosition=position, physicsClientId=client)
    pb.changeDynamics(body, -1, lateralFriction=0.5, physicsClientId=client)
    return body


def _top_grasp(gripper: str, x: float, y: float, palm_z: float, opening: float, **kw) -> GraspPlan:
    T = np.eye(4)
    T[:3, :3] = TOP_DOWN
    T[:3, 3] = [x, y, palm_z]
    return GraspPlan(gripper, "ok", T, 0.06, opening, np.array([1.0, 0.0, 0.0]), **kw)


def _in_hand(hand: Hand, point_robot: np.ndarray) -> np.ndarray:
    T = hand.pose()
    return T[:3, :3].T @ (point_robot - T[:3, 3])


def _urdf_cfg(robot: yourdfpy.URDF, joints: dict[str, float]) -> np.ndarray:
    return np.array([joints[name] for name in robot.actuated_joint_names])


# ---------------------------------------------------------------- hands


def test_specs_carry_the_datasheet_numbers():
    pg70, sdh = GRIPPERS["pg70"], GRIPPERS["sdh"]
    assert pg70.fingers == 2 and pg70.max_aperture_m == pytest.approx(0.065)
    assert [p.name for p in pg70.pads] == ["left", "right"]
    assert all((p.rows, p.cols, p.pitch_m) == (14, 6, 0.0034) for p in pg70.pads)
    assert sdh.fingers == 3 and len(sdh.pads) == 6
    assert sum(p.rows * p.cols for p in sdh.pads) == 486
    assert {p.name for p in sdh.pads} == {
        f"{f}_{part}" for f in ("f1", "f2", "thumb") for part in ("proximal", "distal")
    }


def test_load_parks_the_hand_high_open_and_pointing_down(client):
    hand = Hand.load(client, "pg70")
    for _ in range(30):
        pb.stepSimulation(physicsClientId=client)
    T = hand.pose()
    np.testing.assert_allclose(T[:3, 3], [0.0, 0.0, 2.0], atol=1e-3)
    np.testing.assert_allclose(T[:3, 2], [0.0, 0.0, -1.0], atol=1e-3)
    assert hand.aperture() == pytest.approx(0.065, abs=1e-4)
    with pytest.raises(ConfigError, match="unknown gripper 'nope'"):
        Hand.load(client, "nope")


@pytest.mark.parametrize("gripper", ["pg70", "sdh"])
def test_taxel_frames_follow_the_urdf_kinematics(client, gripper):
    hand = Hand.load(client, gripper)
    T_robot_hand = np.eye(4)
    T_robot_hand[:3, :3] = TOP_DOWN @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0, 0, 1]])
    T_robot_hand[:3, 3] = [0.3, -0.2, 0.6]
    hand.reset_pose(T_robot_hand)
    hand.set_opening(0.05 if gripper == "pg70" else 0.12, np.deg2rad(40.0))
    frames = hand.taxel_frames()
    robot = yourdfpy.URDF.load(str(ROOT / hand.model.urdf))
    robot.update_cfg(_urdf_cfg(robot, hand.joint_positions()))
    for pad in hand.model.pads:
        positions_pad, normals_pad = pad_grid(
            pad.layout.rows,
            pad.layout.cols,
            pad.layout.pitch_m,
            pad.curved_rows,
            pad.curve_radius_m,
        )
        T = T_robot_hand @ robot.get_transform(pad.layout.link, "palm")
        mask = frames.pads == pad.layout.name
        np.testing.assert_array_equal(frames.taxel_indices[mask], np.arange(len(positions_pad)))
        np.testing.assert_allclose(
            frames.positions[mask], positions_pad @ T[:3, :3].T + T[:3, 3], atol=1e-6
        )
        np.testing.assert_allclose(frames.normals[mask], normals_pad @ T[:3, :3].T, atol=1e-6)


def test_sdh_proximal_taxels_span_21_6_to_65_8_mm_from_the_joint(client):
    hand = Hand.load(client, "sdh")
    frames = hand.taxel_frames()
    robot = yourdfpy.URDF.load(str(ROOT / "sdh2.urdf"))
    robot.update_cfg(_urdf_cfg(robot, hand.joint_positions()))
    T_robot_link = hand.pose() @ robot.get_transform("thumb_proximal", "palm")
    taxels = frames.positions[frames.pads == "thumb_proximal"]
    in_link = (taxels - T_robot_link[:3, 3]) @ T_robot_link[:3, :3]
    assert in_link[:, 2].min() == pytest.approx(21.6 * MM, abs=1e-6)
    assert in_link[:, 2].max() == pytest.approx(65.8 * MM, abs=1e-6)
    np.testing.assert_allclose(in_link[:, 0], 15.4 * MM, atol=1e-6)


@pytest.mark.parametrize("opening", [0.06, 0.12, 0.2])
def test_sdh_opening_is_the_distal_pad_circle_diameter_at_60_deg(client, opening):
    hand = Hand.load(client, "sdh")
    hand.set_opening(opening, np.deg2rad(60.0))
    robot = yourdfpy.URDF.load(str(ROOT / "sdh2.urdf"))
    robot.update_cfg(_urdf_cfg(robot, hand.joint_positions()))
    for finger in ("f1", "f2", "thumb"):
        pad = robot.get_transform(f"{finger}_distal_pad", "palm")
        # 10 um: the datasheet's base triangle is rounded (f1 sits 38.104 mm off the axis).
        assert np.hypot(*pad[:2, 3]) == pytest.approx(opening / 2, abs=1e-5)
        # The pad faces the palm axis and is parallel to it.
        np.testing.assert_allclose(pad[:2, 2], -pad[:2, 3] / np.hypot(*pad[:2, 3]), atol=1e-3)
        assert pad[2, 2] == pytest.approx(0.0, abs=1e-6)
    assert hand.aperture() == pytest.approx(opening, abs=1e-5)
    with pytest.raises(ValueError, match="opening"):
        hand.open_configuration(0.3)


# ---------------------------------------------------------------- grasping


def test_pg70_guarded_grasp_closes_on_a_box_without_shoving_it(client):
    width = 0.042
    box = _box(client, [width / 2, 0.04, 0.06], [0.508, 0.1, 0.06])
    hand = Hand.load(client, "pg70")
    # Pad centres 125 mm below the palm: put them 20 mm below the box top.
    plan = _top_grasp("pg70", 0.5, 0.1, 0.12 - 0.02 + 0.125, 0.065)
    outcome = execute_grasp(client, hand, plan, box)
    assert outcome.executed, outcome.reason
    assert outcome.aperture_m == pytest.approx(width, abs=1.0 * MM)
    assert outcome.joint_positions["left_jaw"] + outcome.joint_positions["right_jaw"] == (
        pytest.approx(outcome.aperture_m)
    )
    np.testing.assert_allclose(outcome.T_robot_hand[:3, 3], plan.T_robot_hand[:3, 3], atol=2 * MM)
    # The right jaw arrives first (the box sits 8 mm toward it) and waits at the surface
    # for the left one: the box stays 8 mm off the middle between the pads instead of being
    # pushed there.
    moved = outcome.object_after.position_m - outcome.object_before.position_m
    assert np.linalg.norm(moved) < 1 * MM
    box_in_hand = _in_hand(hand, outcome.object_after.position_m)
    pad_x = [_in_hand(hand, o)[0] for o in hand.pad_poses()[1]]
    assert min(pad_x) < box_in_hand[0] < max(pad_x)
    assert abs(box_in_hand[0]) == pytest.approx(8 * MM, abs=1.5 * MM)
    assert np.all(hand.pad_contact_forces(box) > 1.0)


def test_sdh_grasp_closes_three_fingers_on_a_cylinder(client):
    radius = 0.04
    cylinder = _cylinder(client, radius, 0.12, [0.5, 0.1, 0.06])
    hand = Hand.load(client, "sdh")
    # Straight distal links: distal pad centres 74.5 + 16.5 + 86.5 cos(a) + 42 mm down.
    plan = _top_grasp("sdh", 0.5, 0.1, 0.30, 0.12, spread_rad=np.deg2rad(60.0))
    outcome = execute_grasp(client, hand, plan, cylinder)
    assert outcome.executed, outcome.reason
    forces = dict(zip(hand.pad_ids, hand.pad_contact_forces(cylinder), strict=True))
    for finger in ("f1", "f2", "thumb"):
        assert forces[f"{finger}_distal"] > 0.5
    centre = _in_hand(hand, outcome.object_after.position_m)
    assert np.hypot(centre[0], centre[1]) < 3 * MM
    frames, gaps = hand.taxel_gaps(cylinder, 0.0015, 0.005)
    radii = np.hypot(*_in_hand_many(hand, frames.positions[gaps <= 1 * MM])[:, :2].T)
    assert radii.size >= 3
    np.testing.assert_allclose(radii, radius, atol=1.5 * MM)


def test_sdh_guarded_close_barely_moves_a_light_tall_box(client):
    # A 0.3 kg box, 65 x 130 x 170 mm, tips at about 0.7 N pushed near its top. The palm
    # is 10 mm off its centre toward the fingers, so fingers 1 and 2 (spread 0: facing the
    # thumb) arrive first; they must wait at the surface until the thumb arrives, and then
    # press only about 4 mm further, so the box moves a few millimetres, not centimetres.
    box = _box(client, [0.0325, 0.065, 0.085], [0.5, 0.1, 0.085])
    pb.changeDynamics(box, -1, mass=0.3, physicsClientId=client)
    hand = Hand.load(client, "sdh")
    plan = _top_grasp("sdh", 0.49, 0.1, 0.353, GRIPPERS["sdh"].max_aperture_m, spread_rad=0.0)
    outcome = execute_grasp(client, hand, plan, box)
    assert outcome.executed, outcome.reason
    forces = dict(zip(hand.pad_ids, hand.pad_contact_forces(box), strict=True))
    for finger in ("f1", "f2", "thumb"):
        assert forces[f"{finger}_distal"] > 0.5
    moved = outcome.object_after.position_m - outcome.object_before.position_m
    assert np.hypot(moved[0], moved[1]) < 7 * MM


def _in_hand_many(hand: Hand, points_robot: np.ndarray) -> np.ndarray:
    T = hand.pose()
    return (points_robot - T[:3, 3]) @ T[:3, :3]


def test_regrasp_releases_and_grasps_again(client):
    box = _box(client, [0.021, 0.04, 0.06], [0.5, 0.1, 0.06])
    hand = Hand.load(client, "pg70")
    plan = _top_grasp("pg70", 0.5, 0.1, 0.225, 0.065)
    first = execute_grasp(client, hand, plan, box)
    second = execute_grasp(client, hand, plan, box)
    assert first.executed and second.executed
    assert second.aperture_m == pytest.approx(0.042, abs=1.0 * MM)
    np.testing.assert_allclose(
        second.object_before.position_m, first.object_after.position_m, atol=3 * MM
    )


def test_releasing_an_sdh_grasp_leaves_the_object_where_it_was(client):
    # Fingers 1 and 2 turned to face each other (spread 90 deg) across a 60 mm box: the
    # release opens them and backs off without turning them back about the box (turning
    # them back to spread 0 slid it 6 mm, and a cylinder 40 mm).
    box = _box(client, [0.03, 0.03, 0.085], [0.5, 0.1, 0.085])
    pb.changeDynamics(box, -1, mass=0.3, physicsClientId=client)
    hand = Hand.load(client, "sdh")
    spread = np.pi / 2
    plan = _top_grasp("sdh", 0.5, 0.1, 0.353, 0.11, spread_rad=spread)
    outcome = execute_grasp(client, hand, plan, box)
    assert outcome.executed, outcome.reason
    assert hand.touches(box)
    released = release(client, hand, box, plan.opening_m)
    moved = released.position_m - outcome.object_after.position_m
    assert np.hypot(moved[0], moved[1]) < 2 * MM
    assert not hand.touches(box)


def test_refused_and_impossible_plans_are_not_executed(client):
    box = _box(client, [0.021, 0.04, 0.06], [0.5, 0.1, 0.06])
    hand = Hand.load(client, "pg70")
    parked = hand.pose()
    good = _top_grasp("pg70", 0.5, 0.1, 0.225, 0.065)
    refused = GraspPlan(
        "pg70",
        "refused",
        good.T_robot_hand,
        0.06,
        0.065,
        np.zeros(3),
        reason="object 80 mm wide, aperture 65 mm",
    )
    outcome = execute_grasp(client, hand, refused, box)
    assert not outcome.executed and outcome.reason == "object 80 mm wide, aperture 65 mm"
    assert np.isnan(outcome.aperture_m)
    np.testing.assert_allclose(outcome.T_robot_hand, parked, atol=1e-9)

    too_wide = _top_grasp("pg70", 0.5, 0.1, 0.225, 0.09)
    outcome = execute_grasp(client, hand, too_wide, box)
    assert not outcome.executed and "opening 90.0 mm" in outcome.reason

    inside = _top_grasp("pg70", 0.5, 0.1, 0.08, 0.065)
    inside = GraspPlan("pg70", "ok", inside.T_robot_hand, 0.0, 0.065, np.array([1.0, 0, 0]))
    outcome = execute_grasp(client, hand, inside, box)
    assert not outcome.executed and "overlaps the object" in outcome.reason

    with pytest.raises(ConfigError, match="'sdh'"):
        execute_grasp(
            client, hand, GraspPlan("sdh", "ok", good.T_robot_hand, 0.06, 0.1, np.zeros(3)), box
        )


@pytest.mark.parametrize("guarded", [True, False])
def test_a_jaw_landing_on_the_object_moves_aside_instead_of_shoving_it(client, guarded):
    # A 50 mm box 10 mm off the palm axis towards the left jaw: its edge lies 2.5 mm under
    # the open left jaw (inner face 32.5 mm from the axis), as a calibration error puts it.
    box = _box(client, [0.025, 0.03, 0.04], [0.49, 0.1, 0.04])
    hand = Hand.load(client, "pg70")
    plan = _top_grasp("pg70", 0.5, 0.1, 0.08 - 0.02 + 0.125, 0.065)
    settings = replace(HAND_GRASP_SETTINGS["pg70"], descent_guard_N=1.0 if guarded else 0.0)
    outcome = execute_grasp(client, hand, plan, box, settings)
    moved = np.linalg.norm(outcome.object_after.position_m - outcome.object_before.position_m)
    if guarded:
        # The left jaw opens along -x: one re-approach 4 mm that way clears the edge.
        assert outcome.executed, outcome.reason
        assert outcome.reapproaches == 1
        np.testing.assert_allclose(
            outcome.T_robot_hand[:3, 3], plan.T_robot_hand[:3, 3] - [0.004, 0.0, 0.0], atol=2 * MM
        )
        assert moved < 1 * MM
        assert np.all(hand.pad_contact_forces(box) > 1.0)
    else:
        assert outcome.reapproaches == 0
        assert moved > 2.5 * MM  # the jaw came down on the edge and pushed the box aside


def test_when_every_try_lands_the_hand_descends_blind_on_the_plan(client):
    # 70 mm wide: wider than the open jaws (65 mm), both land wherever the hand goes. The
    # landing side alternates, so the steps go 4, 2, 1 mm; then the plan's own pose.
    box = _box(client, [0.035, 0.03, 0.04], [0.5, 0.1, 0.04])
    hand = Hand.load(client, "pg70")
    plan = _top_grasp("pg70", 0.5, 0.1, 0.08 - 0.02 + 0.125, 0.065)
    outcome = execute_grasp(client, hand, plan, box)
    assert outcome.reapproaches == 3
    np.testing.assert_allclose(outcome.T_robot_hand[:2, 3], plan.T_robot_hand[:2, 3], atol=2 * MM)


def test_a_palm_landing_on_the_object_stops_the_descent(client):
    box = _box(client, [0.025, 0.03, 0.04], [0.5, 0.1, 0.04])
    hand = Hand.load(client, "pg70")
    # The housing reaches 78 mm below the palm: this palm ends 38 mm inside the box.
    plan = _top_grasp("pg70", 0.5, 0.1, 0.08 + 0.04, 0.065)
    outcome = execute_grasp(client, hand, plan, box)
    assert not outcome.executed
    assert "the palm met the object during the descent" in outcome.reason
    assert outcome.reapproaches == 0
    moved = np.linalg.norm(outcome.object_after.position_m - outcome.object_before.position_m)
    assert moved < 2 * MM


def test_pg70_fingers_face_each_other(client):
    hand = Hand.load(client, "pg70")
    facings = hand.model.facings(0.0)
    for origin, facing in zip(hand.pad_poses()[1], facings, strict=True):
        assert _in_hand(hand, origin)[:2] @ facing < -0.02  # the pad closes towards the axis


def test_a_hand_blocked_by_the_table_reports_it(client):
    box = _box(client, [0.021, 0.04, 0.06], [0.7, 0.1, 0.06])  # clear of the hand
    hand = Hand.load(client, "pg70")
    # Fingertips 154 mm below the palm would end 30 mm under the table top.
    plan = _top_grasp("pg70", 0.5, 0.1, 0.124, 0.065)
    plan = GraspPlan("pg70", "ok", plan.T_robot_hand, 0.15, 0.065, plan.closing_direction)
    outcome = execute_grasp(client, hand, plan, box)
    assert not outcome.executed and "blocked" in outcome.reason


def test_object_pose_is_the_link_frame_not_the_centre_of_mass_and_timestep_is_restored(client):
    shape = pb.createCollisionShape(
        pb.GEOM_BOX, halfExtents=[0.021, 0.04, 0.06], physicsClientId=client
    )
    yaw = pb.getQuaternionFromEuler([0.0, 0.0, 0.3])
    box = pb.createMultiBody(
        0.2,
        shape,
        basePosition=[0.5, 0.1, 0.06],
        baseOrientation=yaw,
        baseInertialFramePosition=[0.01, 0.0, -0.02],
        physicsClientId=client,
    )
    pose = object_pose(client, box)
    np.testing.assert_allclose(pose.position_m, [0.5, 0.1, 0.06], atol=1e-9)
    np.testing.assert_allclose(np.abs(pose.quaternion_xyzw @ np.array(yaw)), 1.0, atol=1e-9)

    pb.setTimeStep(1.0 / 500.0, physicsClientId=client)
    hand = Hand.load(client, "pg70")
    execute_grasp(client, hand, _top_grasp("pg70", 0.5, 0.1, 0.225, 0.065), box)
    parameters = pb.getPhysicsEngineParameters(physicsClientId=client)
    assert parameters["fixedTimeStep"] == pytest.approx(1.0 / 500.0)


@pytest.mark.parametrize(
    ("facings", "expected"),
    [
        ([[-1.0, 0.0], [1.0, 0.0]], [True, True]),  # parallel jaws
        (SDH.finger_facings(np.radians(60.0)), [True, True, True]),  # tripod
        (SDH.finger_facings(0.0), [True, True, True]),  # f1, f2 facing the thumb
        (SDH.finger_facings(np.pi / 2), [True, True, False]),  # pinch: thumb alone
        ([[1.0, 0.0], [0.0, 1.0]], [False, False]),  # at right angles
    ],
)
def test_a_finger_presses_only_when_another_closes_against_it(facings, expected):
    assert opposed_fingers(np.array(facings)).tolist() == expected
