"""Lifting a grasped object (:meth:`pipeline.stages.World.lift`) in both simulated worlds:
a box grasped across its thin side by the PG-70 is held 10 cm up for 2 s, a grasp whose
jaws touch one side only leaves it on the table, and a world without the method says
it cannot lift."""

from __future__ import annotations

import importlib.util
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from pipeline.errors import ConfigError
from pipeline.geometry.poses import rotation_z
from pipeline.sim.grasp_sequence import held
from pipeline.testing import AnalyticWorld
from pipeline.types import GraspPlan, SceneSetup

PAD_CENTRE_DEPTH_M = 0.125  # PG-70 pad centres below the palm (robots/pg70.urdf)
LIFT_M, HOLD_S = 0.10, 2.0
WORLDS = [
    "pybullet",
    pytest.param(
        "mujoco",
        marks=pytest.mark.skipif(
            importlib.util.find_spec("mujoco") is None, reason="needs the mujoco package"
        ),
    ),
]


def _box(size_m) -> SimpleNamespace:
    mesh = trimesh.creation.box(size_m)
    mesh.apply_translation((0.0, 0.0, size_m[2] / 2))
    return SimpleNamespace(name="box", mesh=mesh, mass_kg=0.2, friction=0.8, urdf_path=None)


def _grasp_and_lift(name: str, size_m, pad_height_m: float, *, shift_m=0.0, turn_deg=0.0):
    """A box of ``size_m`` in the world ``name``, grasped by the PG-70 from above, jaws
    closing along x (turned ``turn_deg`` about z), palm ``shift_m`` along x from the box's
    centre, pad centres at ``pad_height_m``; then lifted and held."""
    if name == "mujoco":
        from plugins.worlds.mujoco_world import Mujoco as world_class
    else:
        from plugins.worlds.pybullet_world import Pybullet as world_class
    with world_class() as world:
        world.load_scene(SceneSetup(_box(size_m), 0.4, 0.0, 0.0, seed=1))
        world.add_hand("pg70")
        box = world.object_pose().position_m
        T = np.eye(4)
        T[:3, :3] = rotation_z(np.radians(turn_deg)) @ np.diag([1.0, -1.0, -1.0])
        T[:3, 3] = [box[0] + shift_m, box[1], pad_height_m + PAD_CENTRE_DEPTH_M]
        grasp = world.execute_grasp(GraspPlan("pg70", "ok", T, 0.06, 0.065, T[:3, 0].copy()))
        assert grasp.executed, grasp.reason
        return world.lift(LIFT_M, HOLD_S)


@pytest.mark.parametrize("name", WORLDS)
def test_a_box_grasped_across_its_thin_side_is_lifted_and_held(name):
    lifted = _grasp_and_lift(name, (0.042, 0.08, 0.12), 0.65 * 0.12)
    assert lifted.held
    assert lifted.fingers_touching == 2
    # The palm rose the full height; the box rose with it, slipping less than 5 mm.
    assert lifted.hand_rise_m == pytest.approx(LIFT_M, abs=2e-3)
    assert lifted.rise_m == pytest.approx(LIFT_M, abs=5e-3)


@pytest.mark.parametrize("name", WORLDS)
def test_a_box_grasped_askew_turns_square_in_the_grip_and_is_held(name):
    # Closing 10 deg off the thin side, the jaws first meet two edges; the box turns
    # square to them as they press, and the grip presses them on.
    lifted = _grasp_and_lift(name, (0.042, 0.08, 0.12), 0.65 * 0.12, turn_deg=10.0)
    assert lifted.held
    assert lifted.rise_m == pytest.approx(LIFT_M, abs=5e-3)


@pytest.mark.parametrize("name", WORLDS)
def test_a_grasp_touching_one_side_only_leaves_the_box_on_the_table(name):
    # A 12 mm slab 16 mm right of the palm: the left jaw closes to the palm's centre line,
    # 10 mm short of it (beyond the grip's reach), and only the right jaw touches.
    lifted = _grasp_and_lift(name, (0.012, 0.08, 0.10), 0.06, shift_m=-0.016)
    assert not lifted.held
    assert lifted.fingers_touching <= 1
    assert lifted.rise_m < 0.01
    assert lifted.hand_rise_m == pytest.approx(LIFT_M, abs=2e-3)


def test_the_held_rule():
    assert held(0.099, 0.1, 2, 0.02)
    assert held(0.08, 0.1, 3, 0.02)
    assert not held(0.079, 0.1, 2, 0.02)  # slid out (or fell) more than the slip allowed
    assert not held(0.1, 0.1, 1, 0.02)  # hangs on one finger


def test_a_world_without_lift_says_it_cannot_lift():
    world = AnalyticWorld()
    with pytest.raises(ConfigError, match="world 'analytic' cannot lift"):
        world.lift(LIFT_M, HOLD_S)
