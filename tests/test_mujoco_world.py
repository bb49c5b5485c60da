"""The ``mujoco`` world stage: its images against the analytic world's ray caster, its
hands against the URDF's kinematics (yourdfpy), and grasps of a box of known size.

Skipped when the optional ``mujoco`` package is not installed (``pip install -e
'.[mujoco]'``; ``.ci/run`` installs it).
"""

from __future__ import annotations

import math
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

pytest.importorskip("mujoco", reason="the mujoco world needs: pip install -e '.[mujoco]'")

from pipeline.errors import ConfigError
from pipeline.geometry.poses import look_at
from pipeline.registry import load_registry
from pipeline.sim.hand_models import GRIPPERS, HAND_MODELS
from pipeline.testing import AnalyticWorld, tiny_scene
from pipeline.types import CameraIntrinsics, GraspPlan, SceneSetup
from plugins.worlds.mujoco_world import Mujoco
from robots import ROOT

BOX_M = (0.042, 0.08, 0.12)
PAD_CENTRE_DEPTH_M = 0.125  # PG-70 pad centres below the palm (robots/pg70.urdf)
SMALL_CAMERA = CameraIntrinsics(80, 60, 75.0, 75.0, 39.5, 29.5)


def _box(friction: float = 0.8) -> SimpleNamespace:
    mesh = trimesh.creation.box(BOX_M)
    mesh.apply_translation((0.0, 0.0, BOX_M[2] / 2))
    return SimpleNamespace(name="box", mesh=mesh, mass_kg=0.2, friction=friction, urdf_path=None)


def _top_grasp(x: float, y: float, yaw_rad: float, pregrasp_m: float = 0.06) -> GraspPlan:
    """PG-70 from above, jaws closing along the box's thin side, pads at 65 % of its
    height: the housing clears its top by 11 mm."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    T = np.eye(4)
    T[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    T[:3, 3] = [x, y, 0.65 * BOX_M[2] + PAD_CENTRE_DEPTH_M]
    return GraspPlan("pg70", "ok", T, pregrasp_m, 0.065, T[:3, 0].copy())


@pytest.fixture
def world():
    with Mujoco() as world:
        world.load_scene(SceneSetup(_box(), 0.3, -0.1, 0.0, seed=1))
        world.add_hand("pg70")
        yield world


def test_registered_as_world_mujoco_with_the_shipped_hands():
    registration = load_registry().get("world", "mujoco")
    assert registration.cls is Mujoco
    assert Mujoco.hands == tuple(HAND_MODELS) and Mujoco.changes_hands
    assert all(Mujoco().gripper_spec(name) is GRIPPERS[name] for name in Mujoco.hands)
    with pytest.raises(ConfigError, match="world 'mujoco' has no hand 'robotiq'"):
        Mujoco().gripper_spec("robotiq")


def test_a_world_without_a_scene_or_a_hand_says_so():
    with pytest.raises(ConfigError, match="no scene"):
        Mujoco().object_pose()
    with Mujoco() as world:
        world.load_scene(SceneSetup(_box(), 0.3, 0.0, 0.0))
        with pytest.raises(ConfigError, match="no hand"):
            world.taxels(0.0015, 0.005)


def test_without_the_package_loading_a_scene_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # `import mujoco` now fails
    for name in [name for name in sys.modules if name.startswith("pipeline.sim.mujoco")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(ConfigError, match=r"pip install 'symfuse\[mujoco\]'"):
        Mujoco().load_scene(SceneSetup(_box()))


def test_the_object_rests_on_the_table_where_it_was_put():
    with Mujoco({"table_height_m": 0.1}) as world:
        world.load_scene(SceneSetup(_box(), 0.3, -0.1, math.radians(30.0)))
        pose = world.object_pose()
        np.testing.assert_allclose(pose.position_m, [0.3, -0.1, 0.1], atol=2e-4)
        yaw = 2.0 * math.atan2(pose.quaternion_xyzw[2], pose.quaternion_xyzw[3])
        assert yaw == pytest.approx(math.radians(30.0), abs=1e-3)


def test_images_match_the_analytic_worlds_ray_caster():
    """Two independent ray casters (MuJoCo's, open3d's) on the same box and table: the
    same depth wherever both see the same surface, the same object mask but at edges (the
    analytic table has no edge; MuJoCo's, 1 m from the origin, is seen from here)."""
    scene = tiny_scene(x_m=0.3, yaw_rad=math.radians(20.0))
    T = look_at(np.array([0.3, 0.0, 0.06]), 0.6, math.radians(50.0), math.radians(160.0))
    with Mujoco() as world, AnalyticWorld() as oracle:
        world.load_scene(scene)
        oracle.load_scene(scene)
        image = world.render(SMALL_CAMERA, T, 0.05, 3.0)
        truth = oracle.render(SMALL_CAMERA, T, 0.05, 3.0)
    assert image.rgb.shape == (60, 80, 3) and image.rgb.dtype == np.uint8
    assert 100 < image.object_mask.sum() < 1000
    differs = image.object_mask != truth.object_mask
    assert differs.sum() <= 0.05 * truth.object_mask.sum()
    both = (image.object_mask == truth.object_mask) & np.isfinite(image.depth_m)
    assert both.mean() > 0.5
    np.testing.assert_allclose(image.depth_m[both], truth.depth_m[both], atol=1e-4)
    # Nothing beyond the far plane: the table is seen only up to it.
    with Mujoco() as world:
        world.load_scene(scene)
        clipped = world.render(SMALL_CAMERA, T, 0.05, 0.7)
    assert np.nanmax(clipped.depth_m) <= 0.7 and np.isnan(clipped.depth_m).any()


@pytest.mark.parametrize("gripper", ["pg70", "sdh"])
def test_pad_frames_follow_the_urdf_kinematics(gripper):
    """MuJoCo compiled the hand from the same URDF yourdfpy reads: the pad frames agree
    for an opening, with the palm turned and moved."""
    import yourdfpy

    with Mujoco() as world:
        world.load_scene(SceneSetup(_box(), 0.3, 0.0, 0.0))
        world.add_hand(gripper)
        hand = world.sim.hand
        opening = 0.8 * GRIPPERS[gripper].max_aperture_m
        configuration = hand.open_configuration(opening, math.radians(40.0))
        hand.set_opening(opening, math.radians(40.0))
        T = np.eye(4)
        T[:3, :3] = trimesh.transformations.rotation_matrix(2.0, [0.3, 0.4, 0.8])[:3, :3]
        T[:3, 3] = [0.1, -0.2, 0.9]
        hand.reset_pose(T)
        rotations, origins = hand.pad_poses()
        np.testing.assert_allclose(hand.pose(), T, atol=1e-9)
    urdf = yourdfpy.URDF.load(str(ROOT / HAND_MODELS[gripper].urdf))
    urdf.update_cfg({k: v for k, v in configuration.items() if k in urdf.actuated_joint_names})
    for pad, rotation, origin in zip(HAND_MODELS[gripper].pads, rotations, origins, strict=True):
        expected = T @ urdf.get_transform(pad.layout.link, "palm")
        np.testing.assert_allclose(rotation, expected[:3, :3], atol=1e-6)
        np.testing.assert_allclose(origin, expected[:3, 3], atol=1e-6)


def test_a_grasp_closes_on_the_box_and_its_taxels_touch_both_sides(world):
    box = world.object_pose().position_m
    outcome = world.execute_grasp(_top_grasp(box[0], box[1], 0.0))
    assert outcome.executed, outcome.reason
    # The jaws stop on the box: its thickness, up to the pads sinking into it.
    assert outcome.aperture_m == pytest.approx(BOX_M[0], abs=5e-4)
    held = world.taxels(0.0015, 0.001)
    touching = held.gaps_m <= 0.001
    assert set(held.pads[touching]) == {"left", "right"}
    assert set(held.pads[held.pad_forces_N > 1.0]) == {"left", "right"}
    # Taxels in contact lie on the box's faces x = +-21 mm (box frame), pressed in < 0.5 mm.
    local = held.positions[touching] - outcome.object_after.position_m
    assert np.all(np.abs(np.abs(local[:, 0]) - BOX_M[0] / 2) < 5e-4)
    assert np.all(held.gaps_m[touching] > -5e-4)
    moved = outcome.object_after.position_m - outcome.object_before.position_m
    assert np.linalg.norm(moved) < 2e-3


def test_release_withdraws_the_hand_and_a_second_grasp_holds_again(world):
    box = world.object_pose().position_m
    first = world.execute_grasp(_top_grasp(box[0], box[1], 0.0))
    assert first.executed, first.reason
    released = world.release()
    np.testing.assert_allclose(released.position_m, first.object_after.position_m, atol=3e-3)
    assert abs(released.position_m[2] - world.table_height_m) < 1e-3
    free = world.taxels(0.0015, 0.005)
    assert np.all(np.isinf(free.gaps_m)) and np.all(free.pad_forces_N == 0.0)
    assert np.min(free.positions[:, 2]) > 0.5  # parked far above the object
    second = world.execute_grasp(_top_grasp(released.position_m[0], released.position_m[1], 0.0))
    assert second.executed, second.reason
    assert np.sum(world.taxels(0.0015, 0.001).gaps_m <= 0.001) >= 4


def test_a_landing_finger_is_reapproached_and_a_palm_landing_is_refused(world):
    box = world.object_pose().position_m
    # The left jaw lands on the top; the pre-grasp pose has the fingertips above the box.
    off_centre = _top_grasp(box[0] + 0.014, box[1], 0.0, pregrasp_m=0.1)
    outcome = world.execute_grasp(off_centre)
    assert outcome.executed and outcome.reapproaches >= 1
    world.release()
    box = world.object_pose().position_m
    low = _top_grasp(box[0], box[1], 0.0)
    low.T_robot_hand[2, 3] = BOX_M[2] + 0.05  # the palm would have to go into the box
    refused = world.execute_grasp(low)
    assert not refused.executed and "palm" in refused.reason


def test_the_hand_is_changed_for_the_sdh_after_a_release(world):
    box = world.object_pose().position_m
    assert world.execute_grasp(_top_grasp(box[0], box[1], 0.0)).executed
    world.release()
    world.remove_hand()
    assert world.gripper is None
    world.add_hand("sdh")
    taxels = world.taxels(0.0015, 0.005)
    assert set(taxels.pads) == {pad.name for pad in world.gripper.pads}
    assert np.min(taxels.positions[:, 2]) > 0.5
    np.testing.assert_allclose(world.object_pose().position_m, box, atol=3e-3)


@pytest.mark.slow
def test_symfuse_trial_in_mujoco_writes_what_a_pybullet_trial_writes(tmp_path):
    """``symfuse trial --set world.use=mujoco``: every file, and fusion mends the thickness
    the camera's view got wrong (the default CD drive, as in tests/test_trial.py)."""
    import json

    from pipeline.cli import main
    from pipeline.run.trial import PICTURE_FILES, TRIAL_FILES

    assert main(["trial", "--set", "world.use=mujoco", "--out", str(tmp_path)]) == 0
    assert [name for name in TRIAL_FILES + PICTURE_FILES if not (tmp_path / name).is_file()] == []
    stages = json.loads((tmp_path / "result.json").read_text())["stages"]
    assert stages[0]["metrics"]["thickness_error_pct"] > 5.0
    assert stages[2]["metrics"]["thickness_error_pct"] < 1.9
    median = [stage["metrics"]["deviation_m"]["median"] for stage in stages]
    assert median[2] < median[0]
