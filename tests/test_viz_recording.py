"""The Rerun recording of a run, read back with Rerun's own RRD reader."""

from __future__ import annotations

import json
import re
import shutil
import sys

import numpy as np
import pytest
import trimesh

from pipeline.cli import main
from pipeline.io.formats import read_cloud, read_contacts
from pipeline.metrics import point_to_mesh_distances

rerun = pytest.importorskip("rerun")


def read_rrd(path) -> dict[str, list[dict]]:
    """``entity path -> rows in step order``; each row maps a component column (e.g.
    ``Points3D:positions``) to its values as a numpy array, plus ``step``."""
    from rerun.chunk import RrdReader

    rows: dict[str, list[dict]] = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        steps = batch.column("step").to_pylist() if "step" in batch.schema.names else None
        for i in range(batch.num_rows):
            row = {"step": None if steps is None else steps[i]}
            for name in batch.schema.names:
                if ":" in name:
                    row[name] = batch.column(name)[i].values
            rows.setdefault(chunk.entity_path.lstrip("/"), []).append(row)
    return {path: sorted(r, key=lambda row: row["step"] or 0) for path, r in rows.items()}


def positions(row: dict, column: str = "Points3D:positions") -> np.ndarray:
    return np.asarray(row[column].flatten(), dtype=np.float64).reshape(-1, 3)


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    out = tmp_path_factory.mktemp("trial")
    assert main(["trial", "--out", str(out), "--rerun", "--set", "trial.pictures=false"]) == 0
    return out


@pytest.mark.slow
def test_a_trial_recording_holds_every_entity_with_the_runs_sizes(trial):
    rrd = read_rrd(trial / "recording.rrd")
    document = json.loads((trial / "result.json").read_text())
    hand = {"palm", "left_jaw", "right_jaw", "left_pad", "right_pad"}
    plots = [f"plots/plane/{n}" for n in ("theta_deg", "offset_mm")]
    plots += [f"plots/bias/{n}" for n in ("yaw_deg", "x_mm", "y_mm", "z_mm")]
    plots += ["plots/gates/taxels", "plots/gates/points"]
    expected = {
        "world",
        "world/camera",
        "world/camera/image",
        "world/camera/image/depth",
        "world/cloud",
        "world/model",
        "world/plane",
        "world/truth",
        "world/taxels",
        "world/after_view",
        "log",
        *(f"world/hand/{link}" for link in hand),
        *plots,
    }
    assert expected <= set(rrd)

    depth = rrd["world/camera/image/depth"][0]["DepthImage:format"][0].as_py()
    assert (depth["width"], depth["height"]) == (640, 480)

    cloud = read_cloud(trial / "cloud.ply").points
    np.testing.assert_allclose(positions(rrd["world/cloud"][0]), cloud, atol=1e-6)

    # One model per stage, in order, each the stage's completed cloud.
    models = rrd["world/model"]
    assert len(models) == 3
    for k, row in enumerate(models):
        completed = read_cloud(trial / f"completed_stage{k}.ply").points
        np.testing.assert_allclose(positions(row), completed, atol=1e-6)

    # The after-view: the object where the grasp left it, near the cloud.
    after = positions(rrd["world/after_view"][0])
    assert len(after) > len(cloud) / 2
    from scipy.spatial import cKDTree

    assert np.median(cKDTree(cloud).query(after)[0]) < 0.01

    taxels = read_contacts(trial / "contacts.json").contacts[0].positions
    assert all(len(positions(row)) == len(taxels) for row in rrd["world/taxels"])

    truth = trimesh.load(trial / "object_final.ply", force="mesh")
    mesh_row = rrd["world/truth"][0]
    assert len(positions(mesh_row, "Mesh3D:vertex_positions")) == len(truth.vertices)

    # A plane per stage and per IEKF iteration; one value per iteration on every plot.
    traces = [stage["trace"] for stage in document["stages"]]
    iterations = sum(len(trace) for trace in traces)
    assert iterations == sum(stage["iterations"] for stage in document["stages"])
    assert len(rrd["world/plane"]) == 3 + iterations
    for path in plots:
        assert len(rrd[path]) == iterations
    gates = [row["Scalars:scalars"][0].as_py() for row in rrd["plots/gates/taxels"]]
    assert gates == [state["active_taxels"] for trace in traces for state in trace]

    # The hand is where it grasped: every taxel in contact (from the simulator's forward
    # kinematics) lies on its pad's shape (from the URDF's, with the recorded joints).
    contacts = read_contacts(trial / "contacts.json").contacts[0]
    for pad in ("left", "right"):
        row = rrd[f"world/hand/{pad}_pad"][0]
        faces = np.asarray(row["Mesh3D:triangle_indices"].flatten()).reshape(-1, 3)
        vertices = positions(row, "Mesh3D:vertex_positions")
        on_pad = point_to_mesh_distances(contacts.positions[contacts.pads == pad], vertices, faces)
        assert on_pad.max() < 1e-4


def test_view_rebuilds_the_recording_from_the_files(trial, tmp_path, capsys):
    out = tmp_path / "again.rrd"
    assert main(["view", str(trial), "--out", str(out), "--no-open"]) == 0
    assert f"open it with: rerun {out}" in capsys.readouterr().out
    again, first = read_rrd(out), read_rrd(trial / "recording.rrd")
    assert set(again) == set(first)
    assert len(again["world/plane"]) == len(first["world/plane"])


def test_a_fuse_folder_without_camera_or_truth(trial, tmp_path):
    out = tmp_path / "fuse"
    args = ["fuse", "--cloud", str(trial / "cloud.ply"), "--contacts", str(trial / "contacts.json")]
    args += ["--init", "ps"]
    assert main([*args, "--out", str(out), "--rerun"]) in (0, 3)
    rrd = read_rrd(out / "recording.rrd")
    assert "world/camera" not in rrd and "world/truth" not in rrd
    assert {"world/cloud", "world/model", "world/plane", "world/taxels", "world/hand/palm"} <= set(
        rrd
    )


def test_a_folder_of_objects_gets_one_branch_per_object(trial, tmp_path):
    for name in ("object_0", "object_1"):
        shutil.copytree(trial, tmp_path / name, ignore=shutil.ignore_patterns("*.rrd"))
    assert main(["view", str(tmp_path), "--no-open"]) == 0
    rrd = read_rrd(tmp_path / "recording.rrd")
    assert {"world/object_0/model", "world/object_1/model", "plots/object_1/gates/taxels"} <= set(
        rrd
    )


def test_without_the_extra_rerun_is_one_line_naming_it(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun -> ImportError
    assert main(["trial", "--rerun", "--out", str(tmp_path / "t")]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and "symfuse[viz]" in error
    assert not (tmp_path / "t").exists()  # refused before running anything


def test_view_of_a_folder_without_a_run_is_an_error(tmp_path, capsys):
    assert main(["view", str(tmp_path), "--no-open"]) == 2
    assert "no result.json" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("camera.json", '{"x": 1}', "'intrinsics' must be an object"),
        ("camera.json", '{"intrinsics": {"width": 640}}', "intrinsics.height must be a positive"),
        ("depth.npy", b"junk", r"not a \.npy file"),
        ("depth.npy", np.zeros((3, 3, 3)), r"expected an \(H, W\) float depth image"),
    ],
)
def test_a_damaged_camera_or_depth_is_one_line_and_leaves_the_recording(
    trial, tmp_path, capsys, name, content, message
):
    run = tmp_path / "run"
    shutil.copytree(trial, run)
    before = (run / "recording.rrd").read_bytes()
    if isinstance(content, np.ndarray):
        np.save(run / name, content)
    else:
        (run / name).write_bytes(content.encode() if isinstance(content, str) else content)
    assert main(["view", str(run), "--no-open", "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"symfuse: error: {run / name}: ")
    assert re.search(message, err)
    assert (run / "recording.rrd").read_bytes() == before
    assert not list(run.glob(".*partial*"))
