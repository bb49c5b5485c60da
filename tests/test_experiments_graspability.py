"""`symfuse sweep graspability`: its tasks, the models' placement and its report on
hand-made rows."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.experiments import EXPERIMENTS, ExperimentOptions, graspability, objects
from pipeline.geometry.poses import rotation_z
from pipeline.testing import AnalyticWorld, registry_with
from pipeline.types import Bias, Symmetry, SymmetryPlane


def test_the_trials_are_those_of_sweep_objects_with_the_grasps_to_make():
    options = ExperimentOptions(repeats=2)
    tasks = graspability.tasks(options)
    same = {t.key: t for t in objects.tasks(options)}
    assert sorted(t.key for t in tasks) == sorted(same)
    for task in tasks:
        assert task.params == {**same[task.key].params, "grasps": graspability.GRASPS}
        assert task.settings == same[task.key].settings
    # Yaw by yaw, the objects of each yaw in a seeded random order, the same every time.
    yaws = [t.key.split("/")[1] for t in tasks]
    assert yaws == sorted(yaws)
    assert [t.key for t in tasks] == [t.key for t in graspability.tasks(options)]
    labels = [t.params["label"] for t in tasks]
    half = len(labels) // 2
    assert labels[:half] != [t.params["label"] for t in objects.tasks(options)][:half]
    assert EXPERIMENTS["graspability"].reads_scans


def test_a_plane_moves_with_the_object():
    plane = SymmetryPlane.from_normal(np.array([1.0, 0.0]), 0.1)  # x = 0.1
    motion = np.eye(4)
    motion[:3, :3] = rotation_z(np.pi / 2)
    motion[:3, 3] = [0.0, 0.2, 0.0]
    moved = graspability.moved_plane(plane, motion)
    # Points of the plane map onto the moved plane; its normal turned with the object.
    on_plane = np.array([[0.1, -0.3, 0.0], [0.1, 0.5, 0.7]])
    carried = on_plane @ motion[:3, :3].T + motion[:3, 3]
    np.testing.assert_allclose(carried @ moved.normal, moved.offset_m, atol=1e-12)
    np.testing.assert_allclose(moved.normal, [0.0, 1.0, 0.0], atol=1e-12)


def test_a_held_objects_tilt_is_not_carried_to_the_models():
    # The motion back to rest: a turn of 0.5 rad about the vertical after a 2 deg tilt about
    # x (the pads tilting the held object), then a shift. Its planar part is the turn of
    # 0.5 rad (R_z(a) R_x(b) has yaw atan2(sin a (1 + cos b), cos a (1 + cos b)) = a)
    # and moves the pivot where the whole motion does.
    tilt = np.radians(2.0)
    c, s = np.cos(tilt), np.sin(tilt)
    motion = np.eye(4)
    motion[:3, :3] = rotation_z(0.5) @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    motion[:3, 3] = [0.01, -0.02, 0.003]
    pivot = np.array([0.4, 0.05, 0.09])
    planar = graspability.planar_motion(motion, pivot)
    np.testing.assert_allclose(planar[:3, :3], rotation_z(0.5), atol=1e-12)
    np.testing.assert_allclose(
        planar[:3, :3] @ pivot + planar[:3, 3], motion[:3, :3] @ pivot + motion[:3, 3], atol=1e-12
    )
    # A vertical edge stays vertical: its top is not carried 2 deg over.
    top = pivot + np.array([0.0, 0.0, 0.08])
    np.testing.assert_allclose(
        (planar[:3, :3] @ top + planar[:3, 3])[:2],
        (planar[:3, :3] @ pivot + planar[:3, 3])[:2],
        atol=1e-12,
    )
    # A motion with no tilt is its own planar part, whatever the pivot.
    flat = np.eye(4)
    flat[:3, :3] = rotation_z(-1.2)
    flat[:3, 3] = [0.3, 0.1, 0.0]
    np.testing.assert_allclose(graspability.planar_motion(flat, pivot), flat, atol=1e-12)


def _row(label, yaw, stage0, fused, true, **fields):
    grasps = graspability.GRASPS
    row = {
        "key": f"{label}/yaw{yaw:02d}",
        "params": {"label": label},
        "failed": None,
        "fused_stage": 2,
        "stage0_chamfer_mm": 4.0,
        "stage2_chamfer_mm": 2.0,
        "stage0_fscore_5mm": 0.6,
        "stage2_fscore_5mm": 0.8,
        "stage0_iou": 0.5,
        "stage2_iou": 0.7,
    }
    for model, held in zip(graspability.MODELS, (stage0, fused, true), strict=True):
        row |= {
            f"{model}_plans": grasps,
            f"{model}_executed": grasps,
            f"{model}_held": held,
            f"{model}_success": held / grasps,
            f"{model}_first_miss": "" if held == grasps else "dropped: rose 3 mm of 100",
        }
    return row | fields


def test_report_gives_success_per_model_and_object_and_checks_the_claims(tmp_path):
    rows = [
        _row("box", 0, stage0=2, fused=4, true=5),
        _row("box", 1, stage0=3, fused=3, true=4),
        _row("mug", 0, stage0=5, fused=4, true=5),
        {"key": "mug/yaw01", "params": {"label": "mug"}, "failed": "no grasp", "status": "failed"},
        {"key": "can/yaw00", "params": {"label": "can"}, "error": "RuntimeError: boom"},
    ]
    paths = graspability.report(rows, tmp_path)
    assert [p.name for p in paths] == ["results.csv", "graspability.png", "report.md"]
    assert all(p.stat().st_size > 0 for p in paths)
    text = (tmp_path / "report.md").read_text()
    # Means over the three graded trials: Stage 0 10/15, fused 11/15, true 14/15.
    assert "| 5 | 3 | 67 % | 73 % | 93 % | 1 / 1 |" in text
    assert "- fused >= Stage 0: met" in text
    assert "- fused within 10 points of the true mesh: NOT met" in text
    assert "| box | 2 / 2 | 50 % | 70 % | 90 % | 4.0 / 2.0 | 0.60 / 0.80 | 0.50 / 0.70 |" in text
    assert "| mug | 1 / 2 | 100 % | 80 % | 100 % |" in text
    assert "| can | 0 / 1 | - | - | - |" in text
    assert "`mug/yaw01`: no grasp" in text and "`can/yaw00`: RuntimeError: boom" in text
    assert "`box/yaw00` Stage 0: dropped" in text


@pytest.mark.parametrize(
    ("fused", "true", "expected"),
    [(3, 3, (True, True)), (2, 2, (False, True)), (3, 5, (True, False))],
)
def test_claims(fused, true, expected):
    rows = [_row("box", 0, stage0=3, fused=fused, true=true)]
    assert tuple(graspability.claims(rows).values()) == expected


def test_a_world_that_cannot_lift_is_refused_before_any_trial(monkeypatch):
    registry = registry_with(AnalyticWorld)
    monkeypatch.setattr(graspability, "plugin_registry", lambda: registry)
    options = ExperimentOptions(quick=True, config={"world": {"use": "analytic"}})
    with pytest.raises(ConfigError, match="world 'analytic' cannot lift"):
        graspability.tasks(options)


def test_the_models_are_carried_to_the_resting_pose_and_the_truth_lies_on_the_mesh():
    import trimesh

    from pipeline.catalogue.objects import load_object
    from pipeline.types import ObjectPose

    obj = load_object("cd_drive")
    after = ObjectPose(
        np.array([0.41, 0.02, 0.0]), np.array([0.0, 0.0, np.sin(0.05), np.cos(0.05)])
    )
    resting = ObjectPose(np.array([0.40, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]))
    completed = np.array([[0.41, 0.02, 0.05], [0.45, 0.0, 0.1]])
    plane = SymmetryPlane.from_normal(np.array([1.0, 0.0]), 0.41)
    stage = SimpleNamespace(completed=completed, plane=plane, bias=Bias())
    record = SimpleNamespace(
        result=SimpleNamespace(stages=(stage,), selected=stage),
        document={
            "object_pose_after": {
                "position": after.position_m.tolist(),
                "quaternion_xyzw": after.quaternion_xyzw.tolist(),
            }
        },
    )
    models = graspability.planning_models(record, obj, resting, seed=3)
    # By hand: each point's offset from the drive's origin after the grasp, turned back by
    # 0.1 rad, from the resting origin.
    c, s = np.cos(-0.1), np.sin(-0.1)
    offsets = completed - [0.41, 0.02, 0.0]
    expected = np.column_stack(
        [
            0.40 + c * offsets[:, 0] - s * offsets[:, 1],
            s * offsets[:, 0] + c * offsets[:, 1],
            offsets[:, 2],
        ]
    )
    np.testing.assert_allclose(expected[0], [0.40, 0.0, 0.05], atol=1e-12)
    np.testing.assert_allclose(models["stage0"].points, expected, atol=1e-12)
    np.testing.assert_allclose(models["fused"].points, expected, atol=1e-12)
    # The plane x = 0.41 through the drive's origin after the grasp: through the resting
    # origin, turned back by 0.1 rad.
    moved = models["fused"].plane
    np.testing.assert_allclose(moved.normal[:2], [c, s], atol=1e-12)
    np.testing.assert_allclose(np.array([0.40, 0.0, 0.0]) @ moved.normal, moved.offset_m)
    # The true model: points on the mesh where it rests, none on the face it stands on,
    # with the catalogue's mirror plane (x = 0.40 at this pose; the drive's plane is x = 0).
    truth = obj.mesh.copy().apply_transform(resting.transform)
    points = models["true"].points
    assert len(points) == len(completed)
    _, distance, _ = trimesh.proximity.closest_point(truth, points)
    assert np.all(distance < 1e-9)
    assert np.all(points[:, 2] > 1e-6)
    np.testing.assert_allclose(abs(models["true"].plane.normal[0]), 1.0, atol=1e-12)
    np.testing.assert_allclose(abs(models["true"].plane.offset_m), 0.40, atol=1e-12)


def _record(stage, pose):
    return SimpleNamespace(
        result=SimpleNamespace(stages=(stage,), selected=stage),
        document={
            "object_pose_after": {
                "position": pose.position_m.tolist(),
                "quaternion_xyzw": pose.quaternion_xyzw.tolist(),
            }
        },
    )


def test_a_fused_model_is_planned_with_the_plane_it_mirrors_onto():
    # The estimator holds its plane before the bias; the completed model {f_b(p)} U
    # {f_b(f_m(p))} is symmetric about the plane the bias moved. The planner mirrors the
    # cloud it is given through the model's plane: with the plane before the bias it
    # would add a copy turned by twice the bias's yaw.
    from pipeline.catalogue.objects import load_object
    from pipeline.types import ObjectPose

    rng = np.random.default_rng(5)
    seen = rng.uniform([0.35, -0.05, 0.01], [0.40, 0.05, 0.08], (200, 3))
    plane = SymmetryPlane.from_normal(np.array([1.0, 0.2]), 0.43)
    bias = Bias(np.radians(4.0), np.array([0.004, -0.003, 0.001]), np.array([0.4, 0.0, 0.0]))
    completed = np.concatenate([bias.apply(seen), bias.apply(plane.mirror(seen))])
    stage = SimpleNamespace(completed=completed, plane=plane, bias=bias)
    pose = ObjectPose(np.array([0.40, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]))
    models = graspability.planning_models(_record(stage, pose), load_object("cd_drive"), pose, 3)
    for name in ("stage0", "fused"):
        model = models[name]
        # Mirroring through the model's plane swaps its two halves, point for point.
        halves = np.split(model.points, 2)
        np.testing.assert_allclose(model.plane.mirror(halves[0]), halves[1], atol=1e-12)
    # The plane before the bias does not: its mirror image is the turned copy.
    assert np.abs(plane.mirror(completed[:200]) - completed[200:]).max() > 5e-3


def test_a_stage_with_a_mesh_is_planned_on_its_surface(tmp_path):
    # The completed cloud leaves holes where neither the camera nor its mirror image saw
    # (a ball's sides below its equator); the trial's watertight mesh of the stage closes
    # them, and is sampled as the true mesh is: evenly, but the face it stands on.
    import trimesh

    from pipeline.asset.files import obj_text
    from pipeline.catalogue.objects import load_object
    from pipeline.types import ObjectPose

    box = trimesh.creation.box(extents=(0.04, 0.06, 0.08))
    box.apply_translation([0.0, 0.0, 0.04])  # object frame: standing on z = 0
    (tmp_path / "model_stage0.obj").write_text(obj_text([("model", box)]))
    T_robot_object = np.eye(4)
    T_robot_object[:3, :3] = rotation_z(0.3)
    T_robot_object[:3, 3] = [0.42, 0.01, 0.0]
    after = ObjectPose(np.array([0.42, 0.01, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]))
    resting = ObjectPose(np.array([0.40, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]))
    completed = np.zeros((500, 3))
    plane = SymmetryPlane.from_normal(np.array([1.0, 0.0]), 0.42)
    stage = SimpleNamespace(stage=0, completed=completed, plane=plane, bias=Bias())
    record = _record(stage, after)
    record.out_dir = tmp_path
    record.document["model"] = {
        "status": "ok",
        "T_robot_object": T_robot_object.tolist(),
        "files": {"stages": {"0": "model_stage0.obj"}},
    }
    models = graspability.planning_models(record, load_object("cd_drive"), resting, seed=3)
    # By hand: the box turned by 0.3 rad about its base centre, which the object's motion
    # back to rest moves from (0.42, 0.01) to (0.40, 0.0).
    expected = box.copy()
    expected.apply_transform(T_robot_object)
    expected.apply_translation([-0.02, -0.01, 0.0])
    for name in ("stage0", "fused"):
        points = models[name].points
        assert models[name].source == "mesh"
        assert len(points) == len(completed)
        _, distance, _ = trimesh.proximity.closest_point(expected, points)
        assert distance.max() < 1e-6
        assert points[:, 2].min() > 1e-6  # nothing on the face it stands on
        assert np.ptp(points[:, 2]) > 0.07
    # Without a mesh (the trial wrote none), the completed cloud.
    del record.document["model"]
    bare = graspability.planning_models(record, load_object("cd_drive"), resting, seed=3)
    assert bare["stage0"].source == "cloud"
    np.testing.assert_allclose(bare["stage0"].points, completed - [0.02, 0.01, 0.0], atol=1e-12)


def _vertical(normal, point):
    return Symmetry("plane", np.asarray(normal, float), np.asarray(point, float))


def test_the_true_plane_is_the_upright_symmetry_nearest_the_fused_one():
    centre = np.array([0.4, 0.1, 0.05])
    near = SymmetryPlane.from_normal(np.array([np.cos(0.3), np.sin(0.3)]), 0.15)
    lean = np.radians(graspability.UPRIGHT_DEG)
    box = [
        _vertical([1.0, 0.0, 0.0], centre),  # 17 deg from near
        _vertical([0.0, 1.0, 0.0], centre),  # 73 deg
        _vertical([0.0, 0.0, 1.0], centre),  # the horizontal mid-plane: never vertical
    ]
    plane = graspability.true_plane(box, near, centre)
    np.testing.assert_allclose(abs(plane.normal[0]), 1.0, atol=1e-12)
    np.testing.assert_allclose(plane.normal @ centre, plane.offset_m, atol=1e-12)
    # A plane leaning more than UPRIGHT_DEG is not the planner's vertical plane; one leaning
    # less is, projected onto the table's normal.
    steep = [_vertical([np.cos(1.1 * lean), 0.0, np.sin(1.1 * lean)], centre)]
    assert graspability.true_plane(steep, near, centre) is None
    slight = graspability.true_plane(
        [_vertical([np.cos(0.9 * lean), 0.0, np.sin(0.9 * lean)], centre)], near, centre
    )
    np.testing.assert_allclose(abs(slight.normal[0]), 1.0, atol=1e-12)
    # An upright axis: the plane through it parallel to the fused one.
    axis = [Symmetry("axis", np.array([0.0, 0.05, 1.0]), centre)]
    through = graspability.true_plane(axis, near, centre)
    np.testing.assert_allclose(through.normal, near.normal, atol=1e-12)
    np.testing.assert_allclose(through.normal @ centre, through.offset_m, atol=1e-12)
    # A sphere (two axes apart, through its centre): the plane through the centre.
    ball = [
        Symmetry("axis", np.array([1.0, 0.0, 0.3]), centre),
        Symmetry("axis", np.array([0.0, 1.0, 0.4]), centre),
    ]
    round_plane = graspability.true_plane(ball, near, centre)
    np.testing.assert_allclose(round_plane.normal @ centre, round_plane.offset_m, atol=1e-12)
    # Nothing upright (a lying banana): none.
    assert graspability.true_plane([], near, centre) is None
