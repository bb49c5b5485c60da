"""The ``pybullet`` world stage: what it offers through the World contract, and a second
grasp after releasing the first."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from pipeline.errors import ConfigError
from pipeline.registry import load_registry
from pipeline.stages import STAGES, World
from pipeline.types import GraspPlan
from plugins.worlds.pybullet_world import Pybullet

BOX_M = (0.042, 0.08, 0.12)
PAD_CENTRE_DEPTH_M = 0.125  # PG-70 pad centres below the palm (robots/pg70.urdf)


def _box() -> SimpleNamespace:
    mesh = trimesh.creation.box(BOX_M)
    mesh.apply_translation((0.0, 0.0, BOX_M[2] / 2))
    return SimpleNamespace(name="box", mesh=mesh, mass_kg=0.2, friction=0.8, urdf_path=None)


def _top_grasp(x: float, y: float, yaw_rad: float) -> GraspPlan:
    """PG-70 from above, jaws closing along the box's thin side, pads at 60 % height."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    T = np.eye(4)
    T[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    T[:3, 3] = [x, y, 0.6 * BOX_M[2] + PAD_CENTRE_DEPTH_M]
    return GraspPlan("pg70", "ok", T, 0.06, 0.065, T[:3, 0].copy())


def test_the_world_is_the_first_of_seven_stages_and_registered_as_pybullet():
    assert STAGES[0] == "world" and len(STAGES) == 7
    registration = load_registry().get("world", "pybullet")
    assert registration.cls is Pybullet and issubclass(Pybullet, World)
    assert registration.origin.plugin == "pybullet"


def test_the_declared_hands_are_the_simulated_ones():
    from pipeline.sim.hands import GRIPPERS

    assert Pybullet.hands == tuple(GRIPPERS)
    world = Pybullet()
    assert all(world.gripper_spec(name) is GRIPPERS[name] for name in Pybullet.hands)
    with pytest.raises(ConfigError, match="no hand 'robotiq'"):
        world.gripper_spec("robotiq")


def test_a_world_without_a_hand_or_scene_says_so():
    with pytest.raises(ConfigError, match="no scene"):
        Pybullet().object_pose()
    with Pybullet.create(_box(), None, x=0.5) as world, pytest.raises(ConfigError, match="no hand"):
        world.taxels(0.0015, 0.005)


def test_release_withdraws_the_hand_and_a_second_grasp_holds_the_object_again():
    with Pybullet.create(_box(), "pg70", x=0.5, y=0.0, seed=1) as world:
        first = world.execute_grasp(_top_grasp(0.5, 0.0, 0.0))
        assert first.executed, first.reason
        held = world.taxels(0.0015, 0.001)
        assert np.sum(held.gaps_m <= 0.001) >= 4
        assert set(held.pads[held.pad_forces_N > 0.0]) == {"left", "right"}

        after_release = world.release()
        # The object was let go where it was held, and rests on the table.
        np.testing.assert_allclose(
            after_release.position_m, first.object_after.position_m, atol=3e-3
        )
        assert abs(after_release.position_m[2] - world.table_height_m) < 1e-3
        free = world.taxels(0.0015, 0.005)
        assert np.all(np.isinf(free.gaps_m)) and np.all(free.pad_forces_N == 0.0)
        assert np.min(free.positions[:, 2]) > 0.5  # parked far above the object

        box = after_release.position_m
        second = world.execute_grasp(_top_grasp(box[0], box[1], 0.0))
        assert second.executed, second.reason
        np.testing.assert_allclose(
            second.object_before.position_m, after_release.position_m, atol=1e-6
        )
        again = world.taxels(0.0015, 0.001)
        assert np.sum(again.gaps_m <= 0.001) >= 4


def test_a_released_hand_can_be_changed_for_another():
    import pybullet

    assert Pybullet.changes_hands
    with Pybullet.create(_box(), "pg70", x=0.5, y=0.0, seed=1) as world:
        client = world.sim.client
        bodies = pybullet.getNumBodies(physicsClientId=client)
        assert world.execute_grasp(_top_grasp(0.5, 0.0, 0.0)).executed
        world.release()
        world.remove_hand()
        assert world.gripper is None
        with pytest.raises(ConfigError, match="no hand"):
            world.taxels(0.0015, 0.005)
        world.add_hand("sdh")
        # The PG-70 left the simulation whole: the SDH-2 took its place.
        assert pybullet.getNumBodies(physicsClientId=client) == bodies
        assert world.gripper.name == "sdh"
        taxels = world.taxels(0.0015, 0.005)
        assert set(taxels.pads) == {pad.name for pad in world.gripper.pads}
        assert np.min(taxels.positions[:, 2]) > 0.5  # parked far above the object


def test_a_world_that_cannot_change_hands_says_so():
    from pipeline.testing import PARALLEL_HAND, AnalyticWorld

    assert not AnalyticWorld.changes_hands
    world = AnalyticWorld()
    world.add_hand(PARALLEL_HAND)
    with pytest.raises(ConfigError, match="world 'analytic' cannot change its hand"):
        world.remove_hand()
