"""The hand contract: what a world declares about how its pads close
(GripperSpec.closing) is what next-grasp scoring predicts with, and the shipped hands
declare theirs as their kinematics say; the simulated worlds share one base that loads no
engine."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from pipeline.planning import sdh_geometry
from pipeline.planning.grasp_geometry import hand_pose
from pipeline.planning.next_grasp import pad_approaches
from pipeline.sim.hand_models import GRIPPERS
from pipeline.types import ClosingPad, GraspPlan

SDH = sdh_geometry.shipped()  # the SDH-2's kinematics, read from its URDF


def _plan(gripper, yaw_rad, spread_rad=0.0):
    closing = np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    return GraspPlan(
        gripper=gripper,
        status="ok",
        T_robot_hand=hand_pose(np.array([0.4, -0.1, 0.2]), closing),
        pregrasp_height_m=0.1,
        opening_m=0.05,
        closing_direction=closing,
        predicted_contacts=np.array([[0.4, -0.1, 0.05], [0.42, -0.1, 0.07]]),
        spread_rad=spread_rad,
    )


def test_the_sdh_pads_close_from_their_bases_along_the_finger_facings():
    """Checked against the finger kinematics (sdh_geometry), at random yaws and spreads."""
    rng = np.random.default_rng(3)
    for yaw, spread in rng.uniform([-math.pi, 0.0], [math.pi, math.pi / 2], size=(20, 2)):
        plan = _plan("sdh", yaw, spread)
        T = np.asarray(plan.T_robot_hand)
        approaches = pad_approaches(plan, GRIPPERS["sdh"])
        assert [a.name for a in approaches] == ["f1_distal", "f2_distal", "thumb_distal"]
        for approach, base, facing in zip(
            approaches,
            SDH.bases_m,
            SDH.finger_facings(spread),
            strict=True,
        ):
            # The palm's xy plane in R: x the hand's x axis, y its y axis (z points down).
            base_r = T[:2, 3] + base[0] * T[:2, 0] + base[1] * T[:2, 1]
            facing_r = facing[0] * T[:2, 0] + facing[1] * T[:2, 1]
            assert np.allclose(approach.origin_m, [*base_r, 0.06], atol=1e-12)
            assert np.allclose(approach.direction, [*facing_r, 0.0], atol=1e-12)
            assert np.count_nonzero(approach.taxels.row_recess) > 0  # the curved tip rows


def test_the_pg70_jaws_close_on_the_palm_axis_front_pad_first():
    plan = _plan("pg70", 0.7)
    left, right = pad_approaches(plan, GRIPPERS["pg70"])
    assert (left.name, right.name) == ("left", "right")
    assert np.allclose(left.direction, plan.closing_direction)
    assert np.allclose(right.direction, -plan.closing_direction)
    assert np.allclose(left.origin_m, [0.4, -0.1, 0.06]) and np.allclose(
        right.origin_m, left.origin_m
    )
    assert not np.any(left.taxels.row_recess)


def test_a_hand_that_declares_no_closing_pads_is_predicted_to_touch_nothing():
    bare = replace(GRIPPERS["pg70"], closing=())
    assert pad_approaches(_plan("pg70", 0.0), bare) == []
    # A hand of another name with the same declaration closes the same way: nothing is
    # read from the hand's name.
    renamed = replace(GRIPPERS["pg70"], name="other", closing=ClosingPad.jaws("left", "right"))
    assert [a.name for a in pad_approaches(_plan("other", 0.0), renamed)] == ["left", "right"]


def test_the_simulated_worlds_share_a_base_that_loads_no_engine():
    code = (
        "import sys; from plugins.worlds.pybullet_world import Pybullet; "
        "from plugins.worlds.mujoco_world import Mujoco; "
        "from pipeline.shipped_hands import ShippedHandsWorld as B; "
        "assert issubclass(Pybullet, B) and issubclass(Mujoco, B); "
        "print(sorted(m for m in ('pybullet', 'mujoco') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("name", ["pybullet", "mujoco"])
def test_each_world_names_itself_in_its_errors(name):
    from pipeline.errors import ConfigError
    from pipeline.registry import load_registry

    world = load_registry().create("world", name, {})
    with pytest.raises(ConfigError, match=f"world '{name}' has no scene yet"):
        world.object_pose()
    with pytest.raises(ConfigError, match=f"world '{name}' has no hand 'x' \\(hands: pg70, sdh\\)"):
        world.gripper_spec("x")
