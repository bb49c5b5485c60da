"""pipeline.testing: the analytic world against hand-computed images and contacts, and a
whole trial in it with the built-in sensor, segmenter, initialiser, planner, tactile model
and estimator (which therefore need nothing but the World contract)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.config import load_config
from pipeline.errors import ConfigError, PluginError
from pipeline.metrics import point_to_mesh_distances
from pipeline.run.runner import run_estimator
from pipeline.run.trial import run_trial
from pipeline.testing import (
    PARALLEL_HAND,
    AnalyticWorld,
    estimation_problem,
    registry_with,
    tiny_scene,
)
from pipeline.types import CameraIntrinsics, GraspPlan
from plugins.estimators.iekf import IekfEstimator
from plugins.tactile.pybullet_taxels import PybulletTaxels

INTRINSICS = CameraIntrinsics(160, 120, 200.0, 200.0, 79.5, 59.5)


def _looking_down(height_m: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # optical z down, image x along robot x
    T[2, 3] = height_m
    return T


def _grasp(opening_m: float, pad_centre_z_m: float = 0.07) -> GraspPlan:
    T = _looking_down(pad_centre_z_m + 0.125)
    return GraspPlan(PARALLEL_HAND, "ok", T, 0.05, opening_m, np.array([1.0, 0.0, 0.0]))


def test_render_sees_the_box_top_and_the_table_at_their_depths():
    with AnalyticWorld() as world:
        world.load_scene(tiny_scene(thickness_m=0.04, width_m=0.1, height_m=0.12))
        image = world.render(INTRINSICS, _looking_down(1.0), 0.05, 6.0)
    rows, cols = np.mgrid[0:120, 0:160]
    x = (cols - 79.5) / 200.0 * 0.88  # the box top is 0.88 m from the camera
    y = -(rows - 59.5) / 200.0 * 0.88
    on_top = (np.abs(x) < 0.02) & (np.abs(y) < 0.05)
    clear = (np.abs(np.abs(x) - 0.02) > 0.002) & (np.abs(np.abs(y) - 0.05) > 0.002)
    assert np.array_equal(image.object_mask[clear], on_top[clear])
    np.testing.assert_allclose(image.depth_m[clear & on_top], 0.88, atol=1e-5)
    np.testing.assert_allclose(image.depth_m[~image.object_mask], 1.0, atol=1e-5)
    assert image.rgb.dtype == np.uint8 and image.rgb[on_top & clear].any()


def test_pads_close_until_they_touch_and_the_built_in_tactile_model_reads_them():
    press = AnalyticWorld.Params().press_m
    with AnalyticWorld() as world:
        world.load_scene(tiny_scene(thickness_m=0.04))
        world.add_hand(PARALLEL_HAND)
        outcome = world.execute_grasp(_grasp(0.06))
        assert outcome.executed
        assert outcome.aperture_m == pytest.approx(0.04 - 2 * press, abs=1e-6)
        contacts = PybulletTaxels().read(world, outcome)
        # Every taxel of both 6 x 14 pads lies on a box face, pressed in by `press`.
        assert len(contacts) == 2 * 84
        np.testing.assert_allclose(np.abs(contacts.positions[:, 0]), 0.02 - press, atol=1e-6)
        np.testing.assert_allclose(
            contacts.normals, np.sign(-contacts.positions[:, :1]) * [[1.0, 0.0, 0.0]], atol=1e-9
        )
        state = world.taxels(0.0015, 0.005)
        np.testing.assert_allclose(state.gaps_m, -press, atol=1e-5)
        assert np.all(state.pad_forces_N > 0.0)

        world.release()
        free = world.taxels(0.0015, 0.005)
        assert np.all(np.isinf(free.gaps_m)) and not free.pad_forces_N.any()
        again = world.execute_grasp(_grasp(0.06, pad_centre_z_m=0.05))
        assert again.executed and len(PybulletTaxels().read(world, again)) == 2 * 84


def test_a_pad_that_misses_closes_fully_and_an_overlapping_pad_refuses():
    with AnalyticWorld() as world:
        world.load_scene(tiny_scene(thickness_m=0.04, height_m=0.12))
        world.add_hand(PARALLEL_HAND)
        above = world.execute_grasp(_grasp(0.06, pad_centre_z_m=0.25))
        assert above.executed and above.aperture_m == pytest.approx(0.0)
        assert not world.taxels(0.0015, 0.005).pad_forces_N.any()
        inside = world.execute_grasp(_grasp(0.03))
        assert not inside.executed and "overlaps" in inside.reason
        with pytest.raises(ConfigError, match="world's hand is 'parallel'"):
            world.execute_grasp(GraspPlan("other", "ok", np.eye(4), 0.05, 0.06, np.ones(3)))


def test_a_world_without_a_scene_or_hand_says_so():
    world = AnalyticWorld()
    with pytest.raises(ConfigError, match="no scene"):
        world.object_pose()
    world.load_scene(tiny_scene())
    with pytest.raises(ConfigError, match="no hand"):
        world.taxels(0.001, 0.001)
    with pytest.raises(ConfigError, match="no hand 'pg70'"):
        world.add_hand("pg70")


def test_registry_with_adds_a_plugin_and_refuses_a_taken_name():
    registry = registry_with(AnalyticWorld)
    assert registry.get("world", "analytic").origin.plugin == "test"
    assert "pybullet" in registry.names("world")
    assert registry_with(AnalyticWorld, AnalyticWorld).names("world") == registry.names("world")

    class Another(AnalyticWorld):
        """Another world under a name that is taken."""

        name = "pybullet"

    with pytest.raises(PluginError, match="registered twice"):
        registry_with(Another)


def test_the_ready_estimation_problem_is_solved_by_the_built_in_estimator():
    problem, truth = estimation_problem()
    result = run_estimator(IekfEstimator(), problem)
    final = result.stages[-1]
    assert final.status == "converged"
    assert abs(final.plane.theta_rad - truth.theta_rad) < np.radians(0.5)
    assert abs(final.plane.offset_m - truth.offset_m) < 1e-3


def test_a_whole_trial_runs_in_the_analytic_world_with_the_built_in_stages(tmp_path):
    registry = registry_with(AnalyticWorld)
    config = load_config(
        registry,
        overrides=["world.use=analytic", "trial.gripper=parallel", "trial.pictures=false"],
    )
    assert dict(config.choices) == {
        "world": "analytic",
        "sensor": "pybullet-kinect",
        "segmenter": "table-cluster",
        "initialiser": "vc",
        "planner": "top-parallel",
        "tactile": "pybullet-taxels",
        "estimator": "iekf",
    }
    record = run_trial(config, registry, tmp_path / "trial")
    document = json.loads((tmp_path / "trial" / "result.json").read_text())
    assert document["status"] == "converged" and document["gripper"] == PARALLEL_HAND
    assert document["grasp"]["object_shift_mm"] == 0.0  # nothing moves in this world
    assert document["grasp"]["object_turn_deg"] == 0.0

    # The contacts lie on the true surface, pressed in by the pads' press.
    contacts = json.loads((tmp_path / "trial" / "contacts.json").read_text())
    positions = np.array([t["position"] for g in contacts["grasps"] for t in g["taxels"]])
    assert len(positions) >= 20
    from pipeline.catalogue.objects import load_object

    mesh = load_object("cd_drive").mesh
    distances = point_to_mesh_distances(positions, mesh.vertices, mesh.faces)
    assert np.max(distances) < AnalyticWorld.Params().press_m + 1e-5
    # Fusion corrects the thickness the mirrored cloud alone gets wrong.
    errors = [abs(m["thickness_error_pct"]) for m in record.metrics]
    assert errors[2] < errors[0] / 2
