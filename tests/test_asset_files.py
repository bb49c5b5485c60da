"""The model files a run writes: meshes, collision parts and a URDF that PyBullet, yourdfpy
and symfuse itself load."""

from __future__ import annotations

import json

import numpy as np
import pybullet
import pytest
import trimesh

from pipeline.asset.files import write_model
from pipeline.catalogue.objects import load_object
from pipeline.config import ModelSettings
from pipeline.types import Bias, EstimateResult, StageEstimate, SymmetryPlane

#: The box's pose in frame R: turned 30 deg about z, its base centre at (0.5, 0.1, 0.02).
YAW = np.radians(30.0)
CENTRE = np.array([0.5, 0.1, 0.02])
SIZE = (0.04, 0.12, 0.09)


def _rotation() -> np.ndarray:
    c, s = np.cos(YAW), np.sin(YAW)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _result() -> EstimateResult:
    """Two stages of a box seen from its -x side and above (its own frame), mirrored about
    its middle: Stage 0 too thin by 4 mm, Stage 1 right."""
    box = trimesh.creation.box(SIZE).apply_translation([0.0, 0.0, SIZE[2] / 2])
    points, faces = trimesh.sample.sample_surface(box, 30_000, seed=0)
    seen = (box.face_normals[faces] @ [-0.6, 0.0, 0.8] > 0.05) & (points[:, 2] > 0.01)
    stages = []
    for k, half in enumerate((SIZE[0] / 2 - 0.002, SIZE[0] / 2)):
        front = points[seen] * [half / (SIZE[0] / 2), 1.0, 1.0]
        local = np.concatenate([front, front * [-1.0, 1.0, 1.0]])
        completed = local @ _rotation().T + CENTRE
        normal = _rotation()[:, 0]
        plane = SymmetryPlane.from_normal(normal[:2], float(normal @ CENTRE))
        covariance = np.diag([1e-4, 1e-6, 1e-6, 1e-6, 4e-6, 3e-4])
        stages.append(
            StageEstimate(
                k,
                plane,
                Bias(),
                covariance,
                completed[: len(front)],
                completed,
                0,
                "converged",
                0.0,
            )
        )
    return EstimateResult(tuple(stages), selected_stage=1)


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("model")
    _, document = write_model(out, _result(), ModelSettings(density_kg_m3=800.0), 0.02)
    (out / "model.json").write_text(json.dumps(document))
    return out


def test_the_files_are_closed_meshes_in_the_object_frame(model_dir):
    document = json.loads((model_dir / "model.json").read_text())
    assert document["status"] == "ok" and document["selected_stage"] == 1
    mesh = trimesh.load(model_dir / "model.obj", force="mesh")
    assert mesh.is_watertight and mesh.volume == pytest.approx(np.prod(SIZE), rel=0.05)
    assert mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)  # standing on z = 0
    thin = trimesh.load(model_dir / "model_stage0.obj", force="mesh")
    assert thin.is_watertight and thin.volume < mesh.volume
    # The object frame: x along the plane's normal, origin on the table below the model.
    transform = np.array(document["T_robot_object"])
    assert transform[:3, 0] == pytest.approx(_rotation()[:, 0])
    assert transform[:3, 3] == pytest.approx([*CENTRE[:2], 0.02], abs=0.003)
    assert document["mass_kg"] == pytest.approx(800.0 * mesh.volume, rel=1e-6)
    assert document["centre_of_mass_robot_m"] == pytest.approx(
        CENTRE + np.array([0.0, 0.0, SIZE[2] / 2]), abs=0.003
    )
    assert document["symmetry"]["bop"]["symmetries_discrete"][0][0] == -1.0


def test_pybullet_loads_the_urdf_with_its_mass_and_parts(model_dir):
    client = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(str(model_dir / "model.urdf"), physicsClientId=client)
        mass = pybullet.getDynamicsInfo(body, -1, physicsClientId=client)[0]
        shapes = pybullet.getCollisionShapeData(body, -1, physicsClientId=client)
        low, high = pybullet.getAABB(body, -1, physicsClientId=client)
    finally:
        pybullet.disconnect(client)
    document = json.loads((model_dir / "model.json").read_text())
    assert mass == pytest.approx(document["mass_kg"], rel=1e-6)
    assert len(shapes) == document["collision_parts"] >= 1
    mesh = trimesh.load(model_dir / "model.obj", force="mesh")
    # Bullet pads an AABB by its collision margin (a few mm at most).
    assert np.all(np.abs(np.subtract(low, mesh.bounds[0])) < 0.006)
    assert np.all(np.abs(np.subtract(high, mesh.bounds[1])) < 0.006)


def test_yourdfpy_and_symfuse_load_the_urdf(model_dir):
    import yourdfpy

    urdf = yourdfpy.URDF.load(
        str(model_dir / "model.urdf"),
        load_meshes=True,
        build_collision_scene_graph=True,
        load_collision_meshes=True,
    )
    assert urdf.link_map["base_link"].inertial.mass > 0.0
    assert urdf.scene.to_geometry().is_watertight
    assert len(urdf.collision_scene.geometry) >= 1
    obj = load_object(model_dir / "model.urdf")
    mesh = trimesh.load(model_dir / "model.obj", force="mesh")
    assert obj.mesh.volume == pytest.approx(mesh.volume, rel=1e-6)
    assert obj.mass_kg == pytest.approx(
        json.loads((model_dir / "model.json").read_text())["mass_kg"]
    )


def test_a_set_mass_replaces_the_density(tmp_path):
    _, document = write_model(tmp_path, _result(), ModelSettings(mass_kg=0.3), 0.02)
    assert document["mass_kg"] == pytest.approx(0.3)
    assert document["density_kg_m3"] == pytest.approx(0.3 / document["volume_m3"])


def test_a_model_too_small_for_a_surface_writes_nothing(tmp_path):
    result = _result()
    tiny = [
        StageEstimate(
            s.stage, s.plane, s.bias, s.covariance, s.points[:1], s.completed[:2], 0, s.status, 0.0
        )
        for s in result.stages
    ]
    asset, document = write_model(tmp_path, EstimateResult(tuple(tiny)), ModelSettings(), 0.02)
    assert asset is None and document["status"] == "failed"
    assert "at least 4" in document["reason"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_trial_runs_on_the_model_urdf(model_dir, tmp_path):
    """`symfuse trial --mesh RUN/model.urdf`: the model is an object symfuse can grasp."""
    from pipeline.cli import main

    out = tmp_path / "again"
    code = main(["trial", "--mesh", str(model_dir / "model.urdf"),
                 "--set", "trial.pictures=false", "--out", str(out)])  # fmt: skip
    assert code == 0
    document = json.loads((out / "result.json").read_text())
    assert document["stages"][2]["metrics"]["deviation_m"]["median"] < 0.003
    assert document["model"]["status"] == "ok"
