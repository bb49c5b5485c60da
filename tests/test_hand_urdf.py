"""pipeline.io.hand_urdf: the hand geometry read from a URDF against numbers worked out by
hand from the URDF text, the shipped hands' specs reproduced, and a third hand (a wide
two-jaw gripper written here) planned for and grasped with in the analytic world."""

from __future__ import annotations

import dataclasses
import json
import math
from typing import ClassVar

import numpy as np
import pytest

from pipeline.config import load_config
from pipeline.errors import ConfigError
from pipeline.io.hand_urdf import read_hand_geometry
from pipeline.planning.parallel_candidates import ParallelHand
from pipeline.planning.sdh_geometry import shipped
from pipeline.run.trial import run_trial
from pipeline.sim.hand_models import GRIPPERS
from pipeline.testing import PARALLEL_HAND, AnalyticWorld, registry_with
from pipeline.types import (
    Bias,
    ClosingPad,
    GripperSpec,
    PointCloud,
    SymmetryInit,
    SymmetryPlane,
)
from plugins.planners.top_parallel import TopParallel
from robots import ROOT


#: A wide parallel gripper: a 160 x 60 x 50 mm housing, jaws 50 mm below the flange that
#: travel 50 mm each, 30 x 30 mm pads 10 mm apart when closed, 70 mm down the jaws, whose
#: fingers reach 90 mm and stand 2 mm behind the pads.
def _link(name: str, xyz: str, size: str) -> str:
    """A link with one collision box ``size`` at ``xyz`` in its frame."""
    box = f'<origin xyz="{xyz}" rpy="0 0 0"/><geometry><box size="{size}"/></geometry>'
    return f'<link name="{name}"><collision>{box}</collision></link>'


def _joint(name: str, kind: str, parent: str, child: str, origin: str, extra: str = "") -> str:
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f"<origin {origin}/>{extra}</joint>"
    )


def _jaw(side: str, axis: int, box_x: float, pad_x: float, roll: float) -> str:
    """One jaw: a prismatic joint 50 mm below the flange, a 10 x 50 x 90 mm finger, and a
    30 x 30 mm pad 70 mm down it."""
    travel = f'<axis xyz="{axis} 0 0"/><limit lower="0" upper="0.05" effort="100" velocity="0.05"/>'
    return "\n".join(
        [
            _joint(f"{side}_jaw", "prismatic", "palm", f"{side}_jaw", 'xyz="0 0 0.05"', travel),
            _link(f"{side}_jaw", f"{box_x} 0 0.045", "0.01 0.05 0.09"),
            _joint(
                f"{side}_pad_mount",
                "fixed",
                f"{side}_jaw",
                f"{side}_pad",
                f'xyz="{pad_x} 0 0.07" rpy="{roll} -1.570796 0"',
            ),
            _link(f"{side}_pad", "0 0 -0.001", "0.03 0.03 0.002"),
        ]
    )


@pytest.fixture(scope="module")
def wide_urdf(tmp_path_factory):
    parts = [
        '<?xml version="1.0"?>',
        '<robot name="wide">',
        _link("palm", "0 0 0.025", "0.16 0.06 0.05"),
        _jaw("left", -1, -0.012, -0.005, 3.141593),
        _jaw("right", 1, 0.012, 0.005, 0),
        "</robot>",
    ]
    path = tmp_path_factory.mktemp("hand") / "wide.urdf"
    path.write_text("\n".join(parts))
    return path


def test_the_pg70_geometry_is_the_sums_of_its_urdf_numbers():
    g = read_hand_geometry(ROOT / "pg70.urdf")
    assert g.fingers == ("left", "right")
    left = g.pad("left")
    # Jaw joint 79 mm below the flange, pad mount 46 mm down the jaw.
    assert left.centre_m == (0.0, 0.0, 0.079 + 0.046)
    assert left.normal == (1.0, 0.0, 0.0) and g.pad("right").normal == (-1.0, 0.0, 0.0)
    # The finger box (75 mm from the jaw origin) ends at 79 + 75 = 154 mm: 29 mm below the
    # pad's centre; its face at x = -8 + 5 = -3 mm, 3 mm behind the pad's surface at 0.
    assert left.centre_to_fingertip_m == pytest.approx(0.154 - 0.125, abs=1e-12)
    assert left.recess_m == pytest.approx(0.003, abs=1e-12)
    assert (left.length_m, left.width_m) == (0.05, 0.022)
    assert g.housing.depth_m == 0.078
    assert (g.housing.half_length_m, g.housing.half_width_m) == (0.056, 0.04)
    assert g.fingertip_depth_m == 0.154
    assert g.jaw_half_width_m == 0.02  # the jaw's 40 mm wide base
    assert g.jaw_travel_m == 2 * 0.0325
    assert g.bending == ()
    assert g.closing == ClosingPad.jaws("left", "right")


def test_the_sdh2_fingers_are_read_from_their_joints_and_links():
    g = read_hand_geometry(ROOT / "sdh2.urdf")
    assert g.fingers == ("f1", "f2", "thumb")
    f1, f2, thumb = g.bending
    assert (f1.base_m, f2.base_m, thumb.base_m) == (
        (0.01905, 0.033),
        (0.01905, -0.033),
        (-0.03811, 0.0),
    )
    assert (f1.spread_sign, f2.spread_sign, thumb.spread_sign) == (1, -1, 0)
    assert (f1.facing, f2.facing, thumb.facing) == ((-1.0, 0.0), (-1.0, 0.0), (1.0, 0.0))
    for finger in g.bending:
        assert finger.base_depth_m == 0.0745
        assert finger.knuckle_length_m == 0.0165 and finger.knuckle_radius_m == 0.0145
        assert finger.proximal_length_m == 0.0865 and finger.distal_length_m == 0.0685
        assert finger.half_width_m == 0.029 / 2
        assert finger.proximal_back_m == -0.028 / 2
        assert finger.proximal_pad_offset_m == 0.0154
        assert finger.distal_back_m == -0.0061 - 0.0222 / 2  # the distal link's back box
        assert finger.distal_pad_offset_m == 0.0148 and finger.distal_pad_centre_m == 0.042
        assert finger.bend_limit_rad == pytest.approx(math.pi / 2, abs=1e-6)
    assert g.housing.depth_m == 0.0745 and g.housing.radius_m == 0.0525
    assert g.fingertip_depth_m == pytest.approx(0.0745 + 0.0165 + 0.0865 + 0.0685, abs=1e-12)
    # The distal pad centre 42 mm up the 68.5 mm distal link: 26.5 mm from the tip.
    assert g.pad("thumb_distal").centre_to_fingertip_m == pytest.approx(0.0265, abs=1e-12)
    assert [c.pad for c in g.closing] == ["f1_distal", "f2_distal", "thumb_distal"]
    assert g.jaw_travel_m == 0.0


def test_the_shipped_specs_keep_the_numbers_planners_used_before():
    pg70, sdh = GRIPPERS["pg70"], GRIPPERS["sdh"]
    assert (pg70.fingers, pg70.max_aperture_m, pg70.finger_length_m) == (2, 0.065, 0.154)
    assert (sdh.fingers, sdh.finger_length_m) == (3, 0.246)
    assert sdh.max_aperture_m == pytest.approx(shipped().opening_for_alpha(-math.pi / 2), abs=1e-12)
    hand = ParallelHand.of(pg70, "top-parallel")
    assert (hand.palm_to_pad_centre_m, hand.pad_centre_to_fingertip_m) == (0.125, 0.029)
    assert (hand.finger_recess_m, hand.jaw_half_width_m) == (0.003, 0.04 / 2)
    assert (hand.housing_half_length_m, hand.housing_half_width_m) == (0.112 / 2, 0.08 / 2)
    assert hand.housing_depth_m == 0.078
    curved = [c for c in sdh.closing if c.curved_rows]
    assert [(c.curved_rows, c.curve_radius_m) for c in curved] == [(9, 0.059)] * 3


def test_a_third_hand_is_read_from_its_urdf(wide_urdf):
    g = read_hand_geometry(wide_urdf)
    left = g.pad("left")
    assert left.centre_m == pytest.approx((-0.005, 0.0, 0.05 + 0.07), abs=1e-12)
    assert left.centre_to_fingertip_m == pytest.approx(0.05 + 0.09 - 0.12, abs=1e-12)
    assert left.recess_m == pytest.approx(0.002, abs=1e-12)
    assert (left.length_m, left.width_m) == (0.03, 0.03)
    assert g.jaw_travel_m == pytest.approx(0.01 + 2 * 0.05, abs=1e-12)
    assert g.jaw_half_width_m == 0.025
    assert (g.housing.depth_m, g.housing.half_length_m, g.housing.half_width_m) == (
        0.05,
        0.08,
        0.03,
    )
    world = AnalyticWorld(AnalyticWorld.Params(hand_urdf=str(wide_urdf)))
    spec = world.gripper_spec(PARALLEL_HAND)
    assert spec.max_aperture_m == g.jaw_travel_m and spec.finger_length_m == 0.14
    # As many 3.4 mm taxels as fit the 30 mm pads.
    assert [(p.rows, p.cols) for p in spec.pads] == [(8, 8), (8, 8)]


def test_a_file_that_is_no_hand_is_refused_naming_the_key(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text('<robot name="arm"><link name="base"/></robot>')
    with pytest.raises(ConfigError, match=r"world.analytic.hand_urdf.*no pad link"):
        AnalyticWorld(AnalyticWorld.Params(hand_urdf=str(path)))
    with pytest.raises(ConfigError, match=r"world.analytic.hand_urdf.*not a parallel gripper"):
        AnalyticWorld(AnalyticWorld.Params(hand_urdf="sdh2.urdf"))
    with pytest.raises(ConfigError, match="needs a parallel gripper read from its URDF"):
        ParallelHand.of(GripperSpec("bare", 2, 0.06, GRIPPERS["pg70"].pads, 0.15), "p")


def test_top_parallel_places_the_third_hand_by_its_own_geometry(wide_urdf):
    spec = AnalyticWorld(AnalyticWorld.Params(hand_urdf=str(wide_urdf))).hand
    # The camera-side face and the top of a 42 mm thick box standing at x = 0.6 m.
    ys, zs = np.arange(-0.074, 0.075, 0.004), np.arange(0.002, 0.12, 0.004)
    front = [(0.579, y, z) for y in ys for z in zs]
    top = [(x, y, 0.12) for x in np.arange(0.581, 0.621, 0.004) for y in ys]
    cloud = PointCloud(np.array(front + top), viewpoint_m=np.array([0.0, 0.0, 0.7]))
    proposal = SymmetryInit(plane=SymmetryPlane(0.0, 0.6), bias=Bias())
    plans = {
        name: TopParallel(TopParallel.Params(strategy="paper")).plan(cloud, proposal, hand)
        for name, hand in (("wide", spec), ("pg70", GRIPPERS["pg70"]))
    }
    assert all(plan.status == "ok" for plan in plans.values())
    assert plans["wide"].opening_m == pytest.approx(0.11)
    # The wide pads' 27.2 mm grid (8 rows) sits with its top edge where the PG-70's
    # 47.6 mm grid does, 5 mm below the top; its palm 120 mm above the pad centre, not 125.
    pad_centre = {"wide": 0.12 - 0.005 - 0.0136, "pg70": 0.12 - 0.005 - 0.0238}
    for name, palm_to_pad in (("wide", 0.12), ("pg70", 0.125)):
        assert plans[name].T_robot_hand[2, 3] == pytest.approx(
            pad_centre[name] + palm_to_pad, abs=0.004
        )


@pytest.mark.slow
def test_a_trial_runs_with_the_third_hand(wide_urdf, tmp_path):
    # The wide hand is the analytic world's "parallel" hand, planned by top-parallel.
    hand = f"world.analytic.hand_urdf={json.dumps(str(wide_urdf))}"
    settings = ("world.use=analytic", hand, "trial.gripper=parallel", "trial.pictures=false")
    registry = registry_with(AnalyticWorld)
    run_trial(load_config(registry, overrides=list(settings)), registry, tmp_path / "trial")
    document = json.loads((tmp_path / "trial" / "result.json").read_text())
    assert document["gripper"] == PARALLEL_HAND and document["status"] == "converged"
    # Both pads touched, each an 8 x 8 grid; the jaws closed onto the 42 mm thick CD drive.
    contacts = json.loads((tmp_path / "trial" / "contacts.json").read_text())
    taxels = [t for g in contacts["grasps"] for t in g["taxels"]]
    assert {t["pad"] for t in taxels} == {"left", "right"}
    assert max(t["index"] for t in taxels) < 64
    grasp = document["grasp"]
    assert set(grasp["joint_positions"]) == {"left_jaw", "right_jaw"}
    assert grasp["aperture_m"] == pytest.approx(0.042, abs=0.002)


def _wide_world(urdf):
    """A PyBullet world offering the wide gripper next to the shipped hands, and a planner
    naming it (what a plugin adding a hand registers)."""
    from plugins.worlds.pybullet_world import Pybullet

    class WidePybullet(Pybullet):
        """The pybullet world with the wide gripper."""

        name = "pybullet-wide"
        extra_hands: ClassVar[dict[str, str]] = {"wide": str(urdf)}

    class WideParallel(TopParallel):
        """top-parallel for the wide gripper."""

        name = "wide-parallel"
        grippers = ("wide",)

    return WidePybullet, WideParallel


def test_a_simulated_world_offers_a_hand_named_by_its_urdf(wide_urdf):
    from pipeline.sim.hand_models import GRIPPERS, HAND_MODELS, hand_model

    world_class, _ = _wide_world(wide_urdf)
    assert world_class.hands == ("pg70", "sdh", "wide")
    spec = world_class().gripper_spec("wide")
    assert spec.name == "wide" and spec.max_aperture_m == pytest.approx(0.11)
    assert [(p.rows, p.cols) for p in spec.pads] == [(8, 8), (8, 8)]
    model = hand_model("wide")
    assert "wide" not in HAND_MODELS and "wide" not in GRIPPERS  # still the shipped hands
    # The 10 mm the pads stand apart with both jaws at 0 is no joint's: 50 mm opens each
    # jaw 20 mm.
    assert model.open_configuration(0.05, 0.0) == pytest.approx(
        {"left_jaw": 0.02, "right_jaw": 0.02}
    )
    assert [f.joints for f in model.fingers] == [("left_jaw",), ("right_jaw",)]
    with pytest.raises(ConfigError, match="has no hand 'other'"):
        world_class().gripper_spec("other")


@pytest.mark.slow
def test_a_pybullet_trial_grasps_with_the_hand_a_plugin_adds(wide_urdf, tmp_path):
    world_class, planner_class = _wide_world(wide_urdf)
    registry = registry_with(world_class, planner_class)
    settings = ("world.use=pybullet-wide", "trial.gripper=wide", "trial.pictures=false")
    run_trial(load_config(registry, overrides=list(settings)), registry, tmp_path / "trial")
    document = json.loads((tmp_path / "trial" / "result.json").read_text())
    assert document["gripper"] == "wide" and document["status"] == "converged"
    contacts = json.loads((tmp_path / "trial" / "contacts.json").read_text())
    assert {t["pad"] for g in contacts["grasps"] for t in g["taxels"]} == {"left", "right"}


def test_the_sdh_candidates_take_the_fingers_of_the_hand_they_are_given():
    from pipeline.planning.sdh_candidates import PINCH_SPREAD_RAD, SdhHand
    from plugins.planners.top_three_finger import TopThreeFinger

    sdh = SdhHand.of(GRIPPERS["sdh"], "top-three-finger")
    assert sdh.pad.name == "f1_distal" and sdh.aperture_m == GRIPPERS["sdh"].max_aperture_m
    # Thumb first, then fingers 1 and 2, 33 mm either side of the closing line.
    assert sdh.parallel_finger_offsets_m() == (0.0, 0.033, -0.033)
    assert sdh.turning_lateral_m() == 0.033
    assert sdh.centre_offset_m(0.0) == pytest.approx((0.01905 - 0.03811) / 2, abs=1e-15)
    assert sdh.centre_offset_m(PINCH_SPREAD_RAD) == 0.01905
    assert sdh.centre_offset_m(math.radians(60.0)) == 0.0
    bare = dataclasses.replace(GRIPPERS["sdh"], geometry=None)
    cloud = PointCloud(np.array([[0.6, 0.0, 0.05], [0.61, 0.0, 0.06]]))
    proposal = SymmetryInit(plane=SymmetryPlane(0.0, 0.6), bias=Bias())
    with pytest.raises(ConfigError, match=r"planner 'top-three-finger'.*turn-and-bend"):
        TopThreeFinger().plan(cloud, proposal, bare)
