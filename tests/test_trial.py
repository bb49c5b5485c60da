"""`symfuse trial` end to end in PyBullet, and `symfuse fuse` reproducing its estimate."""

from __future__ import annotations

import contextlib
import io
import json
import time

import numpy as np
import pytest
import trimesh

from pipeline.cli import main
from pipeline.cli.trial import grasp_line, grasps_summary, run_name
from pipeline.io.formats import read_cloud
from pipeline.reports.tables import TERMINAL_WIDTH
from pipeline.run.trial import PICTURE_FILES, TRIAL_FILES, PhaseTimer


@pytest.fixture(scope="module")
def trial_dir(tmp_path_factory):
    """The default trial's folder; what it printed is in ``stdout.txt`` beside it."""
    out = tmp_path_factory.mktemp("trial")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["trial", "--out", str(out)]) == 0
    (out.parent / "stdout.txt").write_text(printed.getvalue())
    return out


def test_the_output_fits_a_terminal(trial_dir):
    printed = (trial_dir.parent / "stdout.txt").read_text().splitlines()
    assert max(len(line) for line in printed) <= TERMINAL_WIDTH
    assert any(line.startswith("stage  status") for line in printed)


def test_the_grasp_table_fits_a_terminal_at_its_widest():
    # The longest status, two-digit errors and stds, three pads of the SDH-2.
    stage = {
        "metrics": {
            "deviation_m": {"median": 0.0312},
            "plane_angle_error_deg": 11.2,
            "plane_offset_error_mm": 10.4,
        },
        "status": "no_correspondence",
        "consistency": {"consistent": True},
    }
    grasp = {
        "grasp": 2,
        "chosen_by": {"strategy": "information"},
        "gripper": "sdh",
        "pads_in_contact": ["finger1_distal", "finger2_distal", "thumb_distal"],
        "taxels_in_contact": 120,
        "selected_stage": 2,
        "stages": [None, None, stage],
        "uncertainty": {
            "plane_offset_std_mm": 10.3,
            "hidden_side_std_mm": 21.7,
            "hidden_shape_std_mm": 12.4,
        },
    }
    document = {"grasps": [grasp], "stop_reason": "grasps done: 2 of 2"}
    narrow = grasps_summary(document).splitlines()
    assert max(len(line) for line in narrow) <= TERMINAL_WIDTH
    assert "10.3 / 12.4" in narrow[2]
    wide = grasps_summary(document, wide=True).splitlines()
    assert "finger1_distal finger2_distal thumb_distal" in wide[2] and "12.40" in wide[2]


def test_a_mesh_run_is_named_after_its_folder(tmp_path):
    assert run_name("cd_drive") == "cd_drive"
    assert run_name(str(tmp_path / "003_cracker_box" / "textured.obj")) == (
        "003_cracker_box-textured"
    )


def test_trial_writes_every_file(trial_dir):
    missing = [name for name in TRIAL_FILES + PICTURE_FILES if not (trial_dir / name).is_file()]
    assert missing == []


def test_result_records_stages_metrics_poses_and_config(trial_dir):
    document = json.loads((trial_dir / "result.json").read_text())
    assert document["object"] == "cd_drive"
    assert [s["stage"] for s in document["stages"]] == [0, 1, 2]
    assert document["status"] in ("converged", "max_iterations")
    assert document["config"]["estimator"]["use"] == "iekf"
    assert set(document["object_pose_before"]) == {"position", "quaternion_xyzw"}
    assert document["taxels_in_contact"] > 20
    for stage in document["stages"]:
        assert {"deviation_m", "thickness_mm", "plane_angle_error_deg", "chamfer_mm", "iou"} <= set(
            stage["metrics"]
        )
    assert set(document["timings"]) >= {"sensor", "segmenter", "grasp", "estimator"}


def test_fused_model_matches_the_true_object(trial_dir):
    """The default trial shows what fusion does: VC mirrors the CD drive (42 mm thick) about
    a plane a little off its middle, so the completed model is clearly too thin; after the
    grasp it is within the paper's 1.9 % and most completed points lie within 3 mm of the
    true surface."""
    stages = json.loads((trial_dir / "result.json").read_text())["stages"]
    assert stages[0]["metrics"]["thickness_error_pct"] > 5.0
    final = stages[2]["metrics"]
    assert final["thickness_error_pct"] < 1.9
    assert final["deviation_m"]["median"] < stages[0]["metrics"]["deviation_m"]["median"]
    assert final["deviation_m"]["median"] < 0.003
    assert final["plane_angle_error_deg"] < 3.0


def test_outputs_are_in_the_robot_frame_where_the_object_is(trial_dir):
    mesh = trimesh.load(trial_dir / "object_final.ply", force="mesh")
    cloud = read_cloud(trial_dir / "cloud.ply").points
    completed = read_cloud(trial_dir / "completed_stage2.ply").points
    assert len(completed) == 2 * len(cloud)
    lo, hi = mesh.bounds
    inside = np.all((completed > lo - 0.005) & (completed < hi + 0.005), axis=1)
    assert inside.mean() > 0.95
    camera = json.loads((trial_dir / "camera.json").read_text())
    assert camera["intrinsics"]["width"] == 640
    depth = np.load(trial_dir / "depth.npy")
    assert depth.shape == (480, 640)


def test_fuse_on_the_trial_files_reproduces_its_estimate(trial_dir, tmp_path):
    """VC's initial state is its plane with zero bias about the cloud's centroid: exactly
    what ``fuse --plane`` starts from."""
    init = json.loads((trial_dir / "result.json").read_text())["init"]
    assert init["bias"]["translation"] == [0.0, 0.0, 0.0] and init["bias"]["yaw"] == 0.0
    plane = ",".join(repr(v) for v in (*init["plane"]["normal"], init["plane"]["offset"]))
    code = main(
        [
            "fuse",
            "--cloud", str(trial_dir / "cloud.ply"),
            "--contacts", str(trial_dir / "contacts.json"),
            "--config", str(trial_dir / "config.toml"),
            "--plane", plane,
            "--out", str(tmp_path / "fused"),
        ]
    )  # fmt: skip
    assert code == 0
    trial = json.loads((trial_dir / "result.json").read_text())["stages"]
    fused = json.loads((tmp_path / "fused" / "result.json").read_text())["stages"]
    for a, b in zip(trial, fused, strict=True):
        assert a["status"] == b["status"]
        assert a["plane"]["normal"] == pytest.approx(b["plane"]["normal"], abs=1e-9)
        assert a["plane"]["offset"] == pytest.approx(b["plane"]["offset"], abs=1e-9)
        assert a["bias"]["translation"] == pytest.approx(b["bias"]["translation"], abs=1e-9)
        assert a["bias"]["yaw"] == pytest.approx(b["bias"]["yaw"], abs=1e-9)


def test_refused_grasp_is_a_clear_failure(tmp_path, capsys):
    """The coffee can is 102 mm across: the PG-70 opens 65 mm with its pads, so the plan is
    refused, not executed."""
    code = main(["trial", "--object", "coffee", "--gripper", "pg70", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 3
    assert err.startswith("symfuse: error: grasp planner 'top-parallel' refused: ")
    assert len(err.strip().splitlines()) == 1
    document = json.loads((tmp_path / "result.json").read_text())
    assert document["status"] == "failed"
    assert (tmp_path / "depth.png").is_file()  # what was done before the failure is kept


@pytest.mark.slow
def test_pictures_can_be_left_out(tmp_path):
    code = main(["trial", "--set", "trial.pictures=false", "--out", str(tmp_path)])
    assert code == 0
    assert all((tmp_path / name).is_file() for name in TRIAL_FILES)
    assert not any((tmp_path / name).exists() for name in PICTURE_FILES)


@pytest.mark.slow
def test_a_user_urdf_goes_through_a_whole_trial(tmp_path):
    """A URDF whose visual mesh sits off the base frame (like a scan's): the world loads the
    URDF, the ground truth is its visual mesh in the base frame."""
    trimesh.creation.box((0.045, 0.12, 0.10)).export(tmp_path / "brick.obj")
    (tmp_path / "brick.urdf").write_text(
        '<robot name="brick"><link name="base">'
        '<visual><origin xyz="0.01 -0.02 0.05"/><geometry><mesh filename="brick.obj"/>'
        "</geometry></visual>"
        '<collision><origin xyz="0.01 -0.02 0.05"/><geometry><box size="0.045 0.12 0.10"/>'
        "</geometry></collision>"
        '<inertial><mass value="0.3"/><inertia ixx="4e-4" iyy="3e-4" izz="4e-4" ixy="0" '
        'ixz="0" iyz="0"/></inertial></link></robot>'
    )
    out = tmp_path / "out"
    code = main(["trial", "--mesh", str(tmp_path / "brick.urdf"),
                 "--set", "trial.pictures=false", "--out", str(out)])  # fmt: skip
    assert code == 0
    stages = json.loads((out / "result.json").read_text())["stages"]
    assert stages[2]["metrics"]["deviation_m"]["median"] < 0.003


@pytest.mark.slow
def test_a_user_mesh_with_its_true_plane_is_scored_against_it(tmp_path):
    folder = tmp_path / "012_brick"
    folder.mkdir()
    trimesh.creation.box((0.045, 0.08, 0.09)).export(folder / "textured.stl")
    code = main(["trial", "--mesh", str(folder / "textured.stl"), "--symmetry", "-1,0,0",
                 "--set", "trial.pictures=false", "--out", str(tmp_path / "o")])  # fmt: skip
    assert code == 0
    document = json.loads((tmp_path / "o" / "result.json").read_text())
    assert document["config"]["trial"]["symmetry"] == [-1.0, 0.0, 0.0]
    for stage in document["stages"]:
        assert stage["metrics"]["plane_angle_error_deg"] < 5.0


def test_unknown_object_is_one_line_exit_2(tmp_path, capsys):
    code = main(["trial", "--object", "teapot", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("symfuse: error: ")
    assert "teapot" in err and "cd_drive" in err


def test_the_trial_writes_a_closed_model_a_simulator_loads(trial_dir):
    """The CD drive's model: closed, within 10 % of the true volume, its convex parts
    within its bounding box (+2 mm), its URDF loaded by PyBullet with the mass it states."""
    import pybullet

    model = json.loads((trial_dir / "result.json").read_text())["model"]
    mesh = trimesh.load(trial_dir / "model.obj", force="mesh")
    truth = trimesh.load(trial_dir / "object_final.ply", force="mesh")
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(truth.volume, rel=0.10)
    assert all(model["watertight"].values())
    parts = trimesh.load(trial_dir / "model_collision.obj", split_object=True, group_material=False)
    parts = list(parts.geometry.values()) if isinstance(parts, trimesh.Scene) else [parts]
    assert len(parts) == model["collision_parts"]
    for part in parts:
        assert np.all(part.bounds[0] >= mesh.bounds[0] - 0.002)
        assert np.all(part.bounds[1] <= mesh.bounds[1] + 0.002)
    client = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(str(trial_dir / "model.urdf"), physicsClientId=client)
        assert pybullet.getDynamicsInfo(body, -1, physicsClientId=client)[0] == pytest.approx(
            model["mass_kg"]
        )
    finally:
        pybullet.disconnect(client)
    # The model scores beside the point model's: a closed surface covers the unseen base.
    stages = json.loads((trial_dir / "result.json").read_text())["stages"]
    assert stages[2]["metrics"]["mesh_chamfer_mm"] < stages[2]["metrics"]["chamfer_mm"]


def test_the_grasp_line_counts_the_taxels_in_contact_within_the_terminal():
    from pipeline.reports.tables import wrapped

    document = {
        "hand": {"reason": "longjaw (longjaw-normal) scored 0.41, the only feasible grasp"},
        "grasp": {"reapproaches": 0, "object_shift_mm": 1.24, "object_turn_deg": 0.5,
                  "object_tilt_deg": 0.04},
        "grasps": [{"taxels_in_contact": 176, "pads_in_contact": ["left", "right"]}],
    }  # fmt: skip
    line = grasp_line(document)
    assert "; 176 taxels in contact (left, right); the object moved 1.2 mm" in line
    assert max(len(row) for row in wrapped(line).splitlines()) <= TERMINAL_WIDTH
    assert "taxels" not in grasp_line({**document, "grasps": []})


def test_the_phase_timer_adds_up_wall_and_processor_time_per_phase():
    """A phase that computes costs processor time, one that sleeps only wall time; a
    phase entered twice adds up."""
    timer = PhaseTimer()
    with timer.phase("compute"):
        deadline = time.process_time() + 0.02
        while time.process_time() < deadline:
            pass
    for _ in range(2):
        with timer.phase("sleep"):
            time.sleep(0.02)
    assert list(timer.seconds) == list(timer.cpu_seconds) == ["compute", "sleep"]
    assert timer.cpu_seconds["compute"] >= 0.02
    assert timer.seconds["sleep"] >= 0.04
    assert timer.cpu_seconds["sleep"] < timer.seconds["sleep"] / 2
