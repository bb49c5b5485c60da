"""Bad input met by a new user, one verb at a time: every mistake is one line
``symfuse: error: ...`` naming what is wrong, with exit code 2, and no traceback."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from pipeline.catalogue.objects import load_object
from pipeline.cli import main
from pipeline.errors import EXIT_BAD_INPUT, EXIT_INTERRUPTED, ConfigError, InputError
from pipeline.io.camera_file import read_camera
from pipeline.io.captures import depth_from_organised, read_capture
from pipeline.io.formats import read_contacts, write_cloud
from pipeline.run.completion import select_objects


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("symfuse: error: "), err
    return lines[0]


@pytest.mark.parametrize(
    ("argv", "names"),
    [
        (["sweep", "nope"], "sweep: argument EXPERIMENT: invalid choice: 'nope'"),
        (["trial", "--seed", "x"], "trial: argument --seed: expected an integer, got 'x'"),
        (["fuse", "--cloud", "c.ply"], "fuse: the following arguments are required"),
        (
            ["plugins", "--foo"],
            "plugins: unrecognized arguments: --foo (see symfuse plugins --help)",
        ),
        (["complete", "x.pcd", "--wide", "--out", "o"], "see symfuse complete --help"),
        (
            ["trial", "--grasps", "2", "--until-std", "0"],
            "--until-std: expected a number of mm above 0",
        ),
        (
            ["trial", "--grasps", "2", "--until-std", "nan"],
            "expected a number of mm above 0, got nan",
        ),
        ([], "the following arguments are required: VERB"),
    ],
)
def test_command_line_mistakes_are_one_line(capsys, argv, names):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == EXIT_BAD_INPUT
    _, err = capsys.readouterr()
    assert names in one_error_line(err)


# ------------------------------------------------------------------ recorded captures


def camera_document(**changes) -> dict:
    T = np.eye(4)
    T[:3, 3] = [-0.5, 0.0, 0.8]
    document = {
        "intrinsics": {"width": 4, "height": 3, "fx": 5.0, "fy": 5.0, "cx": 2.0, "cy": 1.5},
        "T_robot_camera": T.tolist(),
    }
    for key, value in changes.items():
        if key in document["intrinsics"]:
            document["intrinsics"][key] = value
        else:
            document[key] = value
    return document


def reflected() -> list:
    T = np.eye(4)
    T[0, 0] = -1.0
    return T.tolist()


def bottom_row() -> list:
    T = np.eye(4)
    T[3] = [1.0, 2.0, 3.0, 4.0]
    return T.tolist()


def in_millimetres() -> list:
    T = np.eye(4)
    T[:3, 3] = [-500.0, 0.0, 800.0]
    return T.tolist()


@pytest.mark.parametrize(
    ("text", "names"),
    [
        (json.dumps(camera_document(fx=float("inf"))), "intrinsics.fx must be a positive finite"),
        (json.dumps(camera_document()).replace("-0.5", "1" + "0" * 400), "finite 4x4 matrix"),
        (json.dumps(camera_document(T_robot_camera=reflected())), "is a reflection"),
        (json.dumps(camera_document(T_robot_camera=bottom_row())), "bottom row must be 0 0 0 1"),
        (json.dumps(camera_document(T_robot_camera=in_millimetres())), "looks like millimetres"),
    ],
)
def test_a_camera_file_that_is_no_camera_is_refused(tmp_path, text, names):
    path = tmp_path / "camera.json"
    path.write_text(text)
    with pytest.raises(InputError, match=names):
        read_camera(path)


def test_an_empty_depth_npy_is_an_input_error(tmp_path):
    (tmp_path / "depth.npy").write_bytes(b"")
    with pytest.raises(InputError, match=r"depth\.npy: not a \.npy file"):
        read_capture(tmp_path / "depth.npy")


def test_a_mirrored_organised_cloud_is_named_as_such():
    rows, cols = np.mgrid[0:6, 0:8].astype(np.float64)
    z = np.full_like(rows, 1.0)
    points = np.stack([(cols - 4.0) / 500.0 * z, (rows - 3.0) / 500.0 * z, z], axis=-1)
    depth_from_organised(points, "view.pcd")  # a pinhole image: accepted
    with pytest.raises(InputError, match="mirror image: their x axis"):
        depth_from_organised(points[:, ::-1], "view.pcd")


# ------------------------------------------------------------------ numbers


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_a_float_setting_is_finite(run, value):
    code, _, err = run("config", "--set", f"estimator.iekf.noise_along_normal_m={value}")
    assert code == EXIT_BAD_INPUT
    assert "'estimator.iekf.noise_along_normal_m': expected a finite number" in one_error_line(err)
    code, _, err = run("config", "--set", f"trial.yaw_deg={value}")
    assert "'trial.yaw_deg': expected a finite number" in one_error_line(err)


@pytest.mark.parametrize("key", ["trial.x_m", "trial.y_m"])
def test_an_object_placed_off_the_table_is_refused(run, tmp_path, key):
    code, _, err = run("trial", "--set", f"{key}=5", "--out", str(tmp_path / "out"))
    assert code == EXIT_BAD_INPUT
    assert f"'{key}': must be < 1, got 5.0" in one_error_line(err)
    assert not (tmp_path / "out").exists()


def test_a_negative_seed_is_refused_before_anything_runs(run, capsys, tmp_path):
    code, _, err = run("config", "--set", "trial.seed=-1")
    assert code == EXIT_BAD_INPUT
    assert "'trial.seed': must be >= 0" in one_error_line(err)
    for argv in (["trial", "--seed", "-1"], ["sweep", "fig10", "--seed", "-1"]):
        with pytest.raises(SystemExit) as exit_info:
            main([*argv, "--out", str(tmp_path / "out")])
        assert exit_info.value.code == EXIT_BAD_INPUT
        assert "argument --seed: expected an integer >= 0" in one_error_line(capsys.readouterr()[1])
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("option", ["--workers", "--repeats"])
@pytest.mark.parametrize("value", ["0", "-1"])
def test_sweep_counts_are_positive(capsys, tmp_path, option, value):
    with pytest.raises(SystemExit) as exit_info:
        main(["sweep", "fig10", "--quick", option, value, "--out", str(tmp_path / "out")])
    assert exit_info.value.code == EXIT_BAD_INPUT
    assert f"argument {option}: expected an integer >= 1" in one_error_line(capsys.readouterr()[1])
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------ units


def test_units_mm_on_metres_is_refused(run, recording, tmp_path):
    folder, _, plane = recording
    code, _, err = run("fuse", "--cloud", folder / "cloud.ply", "--contacts",
                       folder / "contacts.json", f"--plane={plane}", "--units", "mm",
                       "--out", tmp_path / "out")  # fmt: skip
    assert code == EXIT_BAD_INPUT
    assert "cloud.ply: the object is" in one_error_line(err)
    assert "looks like metres: drop --units mm" in err
    assert not (tmp_path / "out").exists()


def test_units_mm_on_a_metre_mesh_is_refused(tmp_path):
    trimesh.creation.box((0.04, 0.05, 0.1)).export(tmp_path / "box.stl")
    assert load_object(tmp_path / "box.stl").mesh.extents.max() == pytest.approx(0.1)
    with pytest.raises(InputError, match=r"box\.stl: the object is 0\.1 mm across: looks like"):
        load_object(tmp_path / "box.stl", units="mm")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n", "the mesh is flat"),
        ("v 0 0 0\nv .1 0 0\nv .1 .1 0\nv 0 .1 0\nf 1 2 3\nf 1 3 4\n", "the mesh is flat"),
        (
            "v 0 0 0\nv .05 0 0\nv 0 .05 0\nv nan 0 .05\nf 1 2 3\nf 1 2 4\nf 2 3 4\nf 1 3 4\n",
            "vertex 4 has NaN or infinite coordinates",
        ),
    ],
    ids=["triangle", "square", "nan-vertex"],
)
def test_a_mesh_without_a_solid_is_refused(tmp_path, text, message):
    """A flat mesh hung the simulator's convex decomposition; trimesh dropped a NaN vertex
    and its faces without a word."""
    (tmp_path / "m.obj").write_text(text)
    with pytest.raises(InputError, match=message):
        load_object(tmp_path / "m.obj")


def test_a_urdf_whose_mesh_is_missing_says_which_in_one_line(run, tmp_path):
    (tmp_path / "r.urdf").write_text(
        '<robot name="r"><link name="base"><visual><geometry><mesh filename="nosuch.obj"/>'
        "</geometry></visual></link></robot>"
    )
    code, _, err = run("trial", "--mesh", tmp_path / "r.urdf", "--out", tmp_path / "o")
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err) == (
        f"symfuse: error: {tmp_path / 'r.urdf'}: the URDF has no visual mesh "
        "(Can't find nosuch.obj)"
    )


def test_units_do_not_apply_to_a_catalogue_object(run, tmp_path):
    code, _, err = run("trial", "--object", "cd_drive", "--units", "mm", "--out", tmp_path / "o")
    assert code == EXIT_BAD_INPUT
    assert "'cd_drive' is a catalogue object" in one_error_line(err)
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------ settings a verb ignores


def test_a_set_the_verb_does_not_read_is_refused(run, recording, tmp_path):
    folder, _, plane = recording
    fuse = ["fuse", "--cloud", folder / "cloud.ply", "--contacts", folder / "contacts.json",
            f"--plane={plane}", "--out", tmp_path / "out"]  # fmt: skip
    code, _, err = run(*fuse, "--set", "trial.seed=3")
    assert code == EXIT_BAD_INPUT
    assert "--set trial.seed=3: symfuse fuse does not read [trial]" in one_error_line(err)
    code, _, err = run("complete", folder / "cloud.npy", "--set", "planner.use=top-three-finger",
                       "--out", tmp_path / "out")  # fmt: skip
    assert "symfuse complete does not read [planner]" in one_error_line(err)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["complete", "view.npy", "--set", "sensor.use=pybullet-kinect"],
        ["complete", "view.npy", "--set", "sensor.recorded.path=other.npy"],
        ["trial", "--seed", "2", "--set", "trial.seed=3"],
    ],
)
def test_a_set_that_an_option_overrides_is_refused(run, tmp_path, argv):
    code, _, err = run(*argv, "--out", tmp_path / "out")
    assert code == EXIT_BAD_INPUT
    assert "from its arguments; drop this --set" in one_error_line(err)


@pytest.mark.parametrize(
    ("option", "applies_to"),
    [(["--topic", "/camera/depth"], "a ROS bag"), (["--camera", "camera.json"], "a depth image")],
)
def test_a_capture_option_for_another_kind_of_capture_is_refused(tmp_path, option, applies_to):
    rows, cols = np.mgrid[0:6, 0:8].astype(np.float64)
    points = np.stack([(cols - 4.0) / 500.0, (rows - 3.0) / 500.0, np.ones_like(rows)], -1)
    capture = tmp_path / ("view.npy" if option[0] == "--topic" else "view.pcd")
    if option[0] == "--topic":
        np.save(capture, points[..., 2].astype(np.float32))
    else:
        write_cloud(capture, points.reshape(-1, 3))
    name = option[0].removeprefix("--")
    with pytest.raises(InputError, match=f"sensor.recorded.{name} .--{name}. applies to"):
        read_capture(capture, **{name: option[1]})


def test_object_choice_is_an_ascii_number(run, tmp_path):
    with pytest.raises(ConfigError, match="--object ²: expected all, largest, nearest"):
        select_objects("²", [], None, fusing=False)


# ------------------------------------------------------------------ Ctrl-C


def test_ctrl_c_while_an_extension_initialises_is_an_interruption(run, monkeypatch, tmp_path):
    def import_interrupted(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    monkeypatch.setattr("pipeline.cli._cmd_config", import_interrupted)
    code, _, err = run("config")
    assert code == EXIT_INTERRUPTED
    assert err.strip() == "symfuse: interrupted"


# ------------------------------------------------------------------ view --out, pipes


@pytest.mark.parametrize(
    ("name", "names"),
    [
        ("cloud.ply", "a Rerun recording is a .rrd file"),
        ("old.rrd", "exists; pass --overwrite to replace it"),
        ("missing/new.rrd", "does not exist"),
    ],
)
def test_view_never_writes_over_a_file_it_was_not_given(run, tmp_path, name, names):
    (tmp_path / "cloud.ply").write_text("a run's own cloud")
    (tmp_path / "old.rrd").write_text("an earlier recording")
    code, _, err = run("view", tmp_path, "--no-open", "--out", tmp_path / name)
    assert code == EXIT_BAD_INPUT
    assert names in one_error_line(err)
    assert (tmp_path / "cloud.ply").read_text() == "a run's own cloud"
    assert (tmp_path / "old.rrd").read_text() == "an earlier recording"


def test_a_closed_pipe_ends_the_output_quietly():
    command = [sys.executable, "-c", "import sys; from pipeline.cli import main; "
               "sys.exit(main(['plugins', '--params']))"]  # fmt: skip
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()  # before the first line: like `symfuse plugins --params | head -1`
    _, err = process.communicate(timeout=120)
    assert err.decode() == ""
    assert process.returncode == 0


@pytest.mark.parametrize(
    ("argv", "names"),
    [
        (["objects", "--overwrite"], "--overwrite applies to --export DIR"),
        (["objects", "--format", "stl"], "--format applies to --export DIR"),
        (["sweep", "fig10", "--quick", "--scheduler", "tcp://host:8786"],
         "--scheduler applies to --executor dask"),
    ],
)  # fmt: skip
def test_an_option_that_would_be_ignored_is_refused(run, tmp_path, argv, names):
    out = ["--out", tmp_path / "out"] if argv[0] == "sweep" else []
    code, _, err = run(*argv, *out)
    assert code == EXIT_BAD_INPUT
    assert names in one_error_line(err)


def test_a_pcd_with_negative_width_and_height_is_an_input_error(tmp_path):
    header = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH -2\n"
        "HEIGHT -2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n"
    )
    (tmp_path / "view.pcd").write_text(header + "0 0 1\n" * 4)
    with pytest.raises(InputError, match="no valid WIDTH/HEIGHT"):
        read_capture(tmp_path / "view.pcd")


@pytest.mark.parametrize(
    ("changes", "names"),
    [
        ({"T_robot_cam": np.eye(4).tolist()}, "unknown key 'T_robot_cam'"),
        ({"distortion": [0.0] * 5}, "unknown key 'distortion'"),
    ],
)
def test_a_misspelt_camera_key_is_refused(tmp_path, changes, names):
    document = camera_document()
    document.update(changes)
    (tmp_path / "camera.json").write_text(json.dumps(document))
    with pytest.raises(InputError, match=names):
        read_camera(tmp_path / "camera.json")
    document = camera_document()
    document["intrinsics"]["f_x"] = 5.0
    (tmp_path / "camera.json").write_text(json.dumps(document))
    with pytest.raises(InputError, match=r"unknown key 'intrinsics\.f_x'"):
        read_camera(tmp_path / "camera.json")


@pytest.mark.parametrize(
    ("change", "names"),
    [
        (lambda d: d.update(unit="mm"), "unknown key 'unit'"),
        (lambda d: d["grasps"][0].update(plna={}), r"unknown key 'grasps\[0\]\.plna'"),
        (lambda d: d["grasps"][0]["taxels"][0].update(idx=3), r"taxels\[0\]\.idx'"),
    ],
)
def test_a_misspelt_contacts_key_is_refused(tmp_path, change, names):
    taxel = {"position": [0.5, 0.0, 0.1], "normal": [0.0, 1.0, 0.0], "pad": "left"}
    document = {"frame": "robot", "units": "m", "grasps": [{"taxels": [taxel]}]}
    (tmp_path / "contacts.json").write_text(json.dumps(document))
    read_contacts(tmp_path / "contacts.json")
    change(document)
    (tmp_path / "contacts.json").write_text(json.dumps(document))
    with pytest.raises(InputError, match=names):
        read_contacts(tmp_path / "contacts.json")


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["trial", "--init", ""], "--init"),
        (["trial", "--object="], "--object"),
        (["fuse", "--cloud", "c.ply", "--contacts", "c.json", "--plane=", "--out", "o"],
         "--plane"),
        (["complete", "scan.pcd", "--topic", "", "--out", "o"], "--topic"),
    ],
)  # fmt: skip
def test_an_empty_option_value_is_refused_not_dropped(capsys, argv, option):
    with pytest.raises(SystemExit) as exited:
        main(argv)
    assert exited.value.code == EXIT_BAD_INPUT
    assert one_error_line(capsys.readouterr().err).endswith(
        f"argument {option}: the value is empty (see symfuse {argv[0]} --help)"
    )


def test_a_point_too_far_for_any_unit_gets_no_unit_hint_and_no_warning(tmp_path, capsys):
    from pipeline.io.units import check_distance

    with pytest.raises(InputError) as raised:
        check_distance(np.array([[1e308, 0.0, 0.0], [0.0, 1e308, 1e308]]), "c.json")
    assert str(raised.value) == (
        "c.json: a point lies inf m from the robot base: no tabletop object lies that far, "
        "in metres or millimetres"
    )
    assert capsys.readouterr().err == ""
    with pytest.raises(InputError, match="512 m from the robot base: looks like millimetres"):
        check_distance(np.array([[512.0, 0.0, 0.0]]), "c.json")
    with pytest.raises(InputError, match="512 m from the robot base: no tabletop object"):
        check_distance(np.array([[512.0, 0.0, 0.0]]), "c.json", hint=None)


@pytest.mark.parametrize(
    ("option", "key"), [(["--until-std", "1"], "until_std_mm"), (["--next-grasp", "random"],
                                                                 "next_grasp")]
)  # fmt: skip
def test_an_option_of_later_grasps_in_a_one_grasp_trial_is_refused(run, tmp_path, option, key):
    code, _, err = run("trial", *option, "--out", tmp_path / "o")
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err) == (
        f"symfuse: error: {option[0]} (trial.{key}) applies to a trial of several grasps; "
        "give --grasps N with N > 1"
    )
    assert not (tmp_path / "o").exists()


def test_config_file_sections_a_verb_does_not_read_are_named_in_a_note(run, tmp_path):
    (tmp_path / "c.toml").write_text("[trial]\ngrasps = 2\n")
    cloud = tmp_path / "cloud.npy"
    centre = np.array([0.5, 0.0, 0.1])
    np.save(cloud, np.random.default_rng(0).normal(0.0, 0.02, (200, 3)) + centre)
    (tmp_path / "contacts.json").write_text(json.dumps({"frame": "robot", "units": "m",
        "grasps": [{"taxels": [{"position": [0.5, 0.02, 0.1], "normal": [0, -1, 0],
                                "pad": "left"}]}]}))  # fmt: skip
    code, out, err = run("fuse", "--cloud", cloud, "--contacts", tmp_path / "contacts.json",
                         "--plane=0,1,0", "--config", tmp_path / "c.toml",
                         "--out", tmp_path / "o")  # fmt: skip
    assert code in (0, 3), err
    assert (
        f"note: symfuse fuse does not read [trial], which {tmp_path / 'c.toml'} changes: "
        "those settings have no effect"
    ) in out


def test_misnamed_paths_say_what_they_are(run, tmp_path):
    (tmp_path / "dir.obj").mkdir()
    code, _, err = run("trial", "--mesh", tmp_path / "dir.obj", "--out", tmp_path / "o")
    assert one_error_line(err).endswith("dir.obj: a folder, not a mesh file")
    (tmp_path / "afile").write_text("x")
    code, _, err = run("view", tmp_path / "afile", "--no-open")
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err).endswith("afile: a file, not a run's folder")
    code, _, err = run("sweep", "explore", "--quick", "--scans", tmp_path / "none",
                       "--out", tmp_path / "s")  # fmt: skip
    assert one_error_line(err).endswith("none: no such folder")
    (tmp_path / "scans" / "a").mkdir(parents=True)
    (tmp_path / "scans" / "a" / "textured.obj").write_text("")
    code, _, err = run("sweep", "explore", "--quick", "--scans", tmp_path / "scans",
                       "--out", tmp_path / "s")  # fmt: skip
    assert code == EXIT_BAD_INPUT
    assert "textured.obj: " in one_error_line(err)
    assert not (tmp_path / "s").exists()


# ------------------------------------------------------------ found in a new user's first hour


def test_view_never_replaces_the_run_s_own_recording(run, tmp_path):
    (tmp_path / "recording.rrd").write_text("the --rerun recording")
    code, _, err = run("view", tmp_path, "--no-open")
    assert code == EXIT_BAD_INPUT
    assert "recording.rrd: exists; pass --overwrite to replace it" in one_error_line(err)
    assert (tmp_path / "recording.rrd").read_text() == "the --rerun recording"


def test_view_into_a_folder_it_cannot_write_is_one_line(run, tmp_path):
    # /proc refuses new files to everyone, root included (a chmod'ed folder does not).
    code, _, err = run("view", tmp_path, "--no-open", "--out", "/proc/recording.rrd")
    assert code == EXIT_BAD_INPUT
    assert "cannot write in /proc" in one_error_line(err)


def test_view_of_a_run_folder_it_cannot_write_is_one_line(run, tmp_path, monkeypatch):
    # A read-only run folder, which root (these tests' user in CI) cannot make with chmod.
    import tempfile

    def read_only(*args, dir=None, **kwargs):
        raise PermissionError(13, "Permission denied", str(dir))

    monkeypatch.setattr(tempfile, "TemporaryFile", read_only)
    (tmp_path / "result.json").write_text("{}")
    code, _, err = run("view", tmp_path, "--no-open")
    assert code == EXIT_BAD_INPUT
    assert f"cannot write in {tmp_path} (Permission denied)" in one_error_line(err)
    assert list(tmp_path.iterdir()) == [tmp_path / "result.json"]


@pytest.mark.parametrize("kind", ["file", "read-only"])
def test_a_cache_that_cannot_be_written_names_the_variable(tmp_path, monkeypatch, kind):
    from pipeline.sim.collision import convex_decomposition

    if kind == "file":
        (tmp_path / "cache").write_text("not a folder")
        monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path / "cache"))
    else:
        monkeypatch.setenv("SYMFUSE_CACHE", "/proc/symfuse-cache")
    mesh = trimesh.creation.annulus(0.03, 0.05, 0.04)  # non-convex: needs its parts
    with pytest.raises(ConfigError, match=r"^SYMFUSE_CACHE=.*: cannot keep the convex parts"):
        convex_decomposition(mesh, resolution=10_000)


def test_a_trial_with_an_unwritable_cache_is_exit_2_not_a_plugin_failure(
    run, tmp_path, monkeypatch
):
    trimesh.creation.annulus(0.03, 0.05, 0.04).export(tmp_path / "ring.stl")
    (tmp_path / "cache").write_text("not a folder")
    monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path / "cache"))
    code, _, err = run("trial", "--mesh", tmp_path / "ring.stl", "--out", tmp_path / "o")
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err).startswith(f"symfuse: error: SYMFUSE_CACHE={tmp_path / 'cache'}")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("value", ["false", "no", " 0"])
def test_a_client_reuse_variable_that_is_neither_0_nor_1_names_the_variable(monkeypatch, value):
    from pipeline.sim import world

    monkeypatch.setenv(world.REUSE_VARIABLE, value)  # each read as "reuse" before
    with pytest.raises(ConfigError, match=rf"^SYMFUSE_PYBULLET_REUSE={value}: expected 0"):
        world._reuse_clients()
    monkeypatch.setenv(world.REUSE_VARIABLE, "")
    assert world._reuse_clients()


def test_contacts_that_say_mm_over_metre_data_are_refused(recording, tmp_path):
    folder, _, _ = recording
    document = json.loads((folder / "contacts.json").read_text())
    document["units"] = "mm"
    (tmp_path / "c.json").write_text(json.dumps(document))
    with pytest.raises(InputError, match=r'looks like metres: set the file\'s "units" to "m"'):
        read_contacts(tmp_path / "c.json")


def test_a_contacts_file_in_millimetres_is_read(recording, tmp_path):
    folder, _, _ = recording
    document = json.loads((folder / "contacts.json").read_text())
    metres = read_contacts(folder / "contacts.json").contacts[0].positions
    document["units"] = "mm"
    for grasp in document["grasps"]:
        for taxel in grasp["taxels"]:
            taxel["position"] = [1e3 * v for v in taxel["position"]]
        grasp.pop("plan", None)
    (tmp_path / "c.json").write_text(json.dumps(document))
    np.testing.assert_allclose(read_contacts(tmp_path / "c.json").contacts[0].positions, metres)


def test_a_planner_set_to_its_default_for_another_hand_is_refused(run, tmp_path):
    code, _, err = run("trial", "--gripper", "sdh", "--set", "planner.use=top-parallel",
                       "--out", tmp_path / "o")  # fmt: skip
    assert code == EXIT_BAD_INPUT
    assert "planner 'top-parallel' does not plan for the hand 'sdh'" in one_error_line(err)
    assert not (tmp_path / "o").exists()


def test_a_set_for_an_implementation_not_in_use_is_refused(run, tmp_path):
    code, _, err = run("trial", "--set", "estimator.icp.max_iterations=5", "--out", tmp_path / "o")
    assert code == EXIT_BAD_INPUT
    assert "--set estimator.icp.max_iterations=5: estimator.use is 'iekf'" in one_error_line(err)
    assert not (tmp_path / "o").exists()
    code, _, err = run("trial", "--set", "initialiser.ps.bias=full", "--out", tmp_path / "o")
    assert "initialiser.use is 'vc'" in one_error_line(err)


def test_a_set_for_an_implementation_a_run_may_read_is_accepted(run):
    # Every hand's planner plans with trial.gripper = "auto"; `config` prints any key.
    code, out, _ = run("config", "--set", "estimator.icp.max_iterations=5")
    assert code == 0 and "max_iterations = 5" in out
    from pipeline.cli import check_selected
    from pipeline.config import load_config
    from pipeline.registry import load_registry

    registry = load_registry()
    config = load_config(registry)
    check_selected(["planner.top-three-finger.spread_deg=10"], config, registry)


def test_symmetry_refuses_an_unwritable_out_before_it_searches(run, monkeypatch):
    import pipeline.symmetry.search as search

    def no_search(*args, **kwargs):
        raise AssertionError("searched before checking --out")

    monkeypatch.setattr(search, "mesh_symmetries", no_search)
    code, _, err = run("symmetry", "cd_drive", "--out", "/proc/symmetry.json")
    assert code == EXIT_BAD_INPUT
    assert "/proc/symmetry.json: cannot write" in one_error_line(err)


def test_an_interrupted_symmetry_search_leaves_no_file(run, monkeypatch, tmp_path):
    import pipeline.symmetry.search as search

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(search, "mesh_symmetries", interrupted)
    code, _, _ = run("symmetry", "cd_drive", "--out", tmp_path / "s.json")
    assert code == 130
    assert not (tmp_path / "s.json").exists()


def test_a_warning_is_wrapped_to_the_terminal_width(run):
    """A YCB scan's path made its not-watertight warning 113 columns wide."""
    import logging

    run("config")
    message = "/work/scans/003_cracker_box/textured.obj: mesh is not watertight; " * 3
    lines = logging.lastResort.format(logging.makeLogRecord({"msg": message})).splitlines()
    assert len(lines) == 3 and max(len(line) for line in lines) <= 100
    assert " ".join(line.strip() for line in lines) == message.strip()


def test_a_trial_s_progress_lines_fit_100_columns(capsys):
    """A missed first grasp's progress line was 111-117 columns wide."""
    from pipeline.cli.trial import _progress

    _progress(
        "grasp 1 touched one side only (the object moved 5.0 mm and tilted 0.0 deg); not "
        "fused; grasping again (1 of 2)"
    )
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and max(len(line) for line in lines) <= 100
