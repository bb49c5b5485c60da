"""The threshold-taxels tactile model in symfuse's analytic test world (no physics)."""

from __future__ import annotations

import numpy as np
import pytest
from symfuse_threshold_taxels import ThresholdTaxels, taxel_forces

from pipeline.api import ConfigError, GraspPlan
from pipeline.testing import PARALLEL_HAND, AnalyticWorld, registry_with, tiny_scene

ROWS, COLS, PITCH = 14, 6, 0.0034  # the analytic hand's pads
BOX_HEIGHT = 0.12


def grasp(world: AnalyticWorld, pad_centre_z_m: float):
    """Close the analytic hand's pads across the tiny box's 40 mm, pads centred at z."""
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # fingers down, closing along x
    palm_to_pad_centre_m = world.gripper.geometry.pad("left").centre_m[2]  # from its URDF
    T[:3, 3] = [0.0, 0.0, pad_centre_z_m + palm_to_pad_centre_m]
    plan = GraspPlan(PARALLEL_HAND, "ok", T, 0.05, 0.06, np.array([1.0, 0.0, 0.0]))
    outcome = world.execute_grasp(plan)
    assert outcome.executed, outcome.reason
    return outcome


@pytest.fixture
def world():
    with AnalyticWorld() as world:
        world.load_scene(tiny_scene(thickness_m=0.04, height_m=BOX_HEIGHT))
        world.add_hand(PARALLEL_HAND)
        yield world


def rows_below_the_top(pad_centre_z_m: float) -> int:
    """Pad rows (along the finger, z) whose taxel centres lie below the box's top."""
    z = pad_centre_z_m + (np.arange(ROWS) - (ROWS - 1) / 2) * PITCH
    return int(np.sum(z < BOX_HEIGHT))


def test_a_full_grasp_reports_every_pressed_taxel(world):
    outcome = grasp(world, 0.06)
    contacts = ThresholdTaxels().read(world, outcome)
    assert len(contacts) == 2 * ROWS * COLS
    press = AnalyticWorld.Params().press_m
    np.testing.assert_allclose(np.abs(contacts.positions[:, 0]), 0.02 - press, atol=1e-6)


def test_the_force_threshold_silences_a_pad_whose_force_is_spread_thin(world):
    p = AnalyticWorld.Params()
    pad_force = p.pad_stiffness_N_per_m * p.press_m
    partial_rows = rows_below_the_top(0.11)
    assert 0 < partial_rows < ROWS
    full_share = pad_force / (ROWS * COLS)
    partial_share = pad_force / (partial_rows * COLS)
    threshold = 0.5 * (full_share + partial_share)  # between the two shares
    model = ThresholdTaxels(ThresholdTaxels.Params(min_taxel_force_N=threshold))

    assert len(model.read(world, grasp(world, 0.06))) == 0  # force spread over 84 taxels
    world.release()
    contacts = model.read(world, grasp(world, 0.11))  # the same force on fewer taxels
    assert len(contacts) == 2 * partial_rows * COLS
    assert np.all(contacts.positions[:, 2] < BOX_HEIGHT)


def test_dead_taxels_are_the_same_in_every_grasp_and_set_by_the_seed(world):
    def read(seed: int) -> set[tuple[str, int]]:
        params = ThresholdTaxels.Params(dead_fraction=0.25, dead_seed=seed)
        contacts = ThresholdTaxels(params).read(world, None)
        return set(zip(contacts.pads.tolist(), contacts.taxel_indices.tolist(), strict=True))

    grasp(world, 0.06)
    alive = read(3)
    assert 168 - 60 <= len(alive) <= 168 - 25  # about a quarter of 168 is dead
    world.release()
    grasp(world, 0.06)
    assert read(3) == alive
    assert read(4) != alive


def test_taxel_forces_split_each_pad_force_over_its_touching_taxels():
    pads = np.array(["a", "a", "a", "b", "b"])
    forces = taxel_forces(
        pads, np.array([6.0, 6.0, 6.0, 1.0, 1.0]), np.array([1, 1, 0, 1, 0], bool)
    )
    np.testing.assert_allclose(forces, [3.0, 3.0, 0.0, 1.0, 0.0])


def test_registered_and_validated_through_the_registry():
    registry = registry_with(ThresholdTaxels)
    model = registry.create("tactile", "threshold-taxels", {"min_taxel_force_N": 0.2})
    assert model.params.min_taxel_force_N == 0.2
    with pytest.raises(ConfigError, match="dead_fraction"):
        registry.create("tactile", "threshold-taxels", {"dead_fraction": 1.5})
