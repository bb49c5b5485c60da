"""The command line's promises: the output-folder policy, the exit codes, units, and
`plugins --params` showing the effective defaults."""

from __future__ import annotations

import contextlib
import json
import shutil
import subprocess
import time
import types
from pathlib import Path

import numpy as np
import pytest
import trimesh

from pipeline import hookimpl
from pipeline.catalogue.objects import load_object
from pipeline.errors import (
    EXIT_BAD_INPUT,
    EXIT_ESTIMATE_FAILED,
    EXIT_INTERRUPTED,
    EXIT_PLUGIN_RAISED,
    PluginRaised,
    StageFailure,
)
from pipeline.io.outdir import fresh_folder, staged_output
from pipeline.registry import Origin, PluginManager
from pipeline.stages import Estimator

# ------------------------------------------------------------------ helpers


def fuse_args(recording, out, *extra):
    folder, _, plane = recording
    cloud, contacts = folder / "cloud.ply", folder / "contacts.json"
    return ["fuse", "--cloud", cloud, "--contacts", contacts, f"--plane={plane}", *extra,
            "--out", out]  # fmt: skip


def writing(verb: str, recording, out: Path) -> list:
    """A command line of ``verb`` writing to ``out`` (``--out`` and its value last)."""
    return {
        "fuse": fuse_args(recording, out),
        "trial": ["trial", "--out", out],
        "sweep": ["sweep", "fig10", "--quick", "--out", out],
    }[verb]


def leftovers(parent: Path) -> list[str]:
    """Staging folders a run left in ``parent``."""
    return sorted(p.name for p in parent.iterdir() if ".partial-" in p.name or ".old-" in p.name)


def one_error_line(err: str, start: str = "symfuse: error: ") -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(start), err
    return lines[0]


@contextlib.contextmanager
def read_only(folder: Path):
    """``folder`` made unwritable, even for root (immutable attribute) when possible."""
    folder.mkdir(parents=True, exist_ok=True)
    folder.chmod(0o555)
    immutable = False
    probe = folder / "probe"
    try:
        probe.mkdir()
    except OSError:
        pass
    else:  # root ignores modes: try the immutable attribute
        probe.rmdir()
        if shutil.which("chattr") is None:
            pytest.skip("cannot make a read-only folder here")
        done = subprocess.run(["chattr", "+i", str(folder)], capture_output=True)
        if done.returncode != 0:
            pytest.skip("cannot make a read-only folder here (chattr +i refused)")
        immutable = True
    try:
        yield folder
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
        folder.chmod(0o755)


class Kaput(Estimator):
    """An estimator whose code has a bug."""

    name = "kaput"

    def estimate(self, problem):
        raise ZeroDivisionError("division by zero")


class Refuses(Estimator):
    """An estimator that ran correctly but has no result."""

    name = "refuses"

    def estimate(self, problem):
        raise StageFailure("estimator 'refuses': too few points in the gates")


class Interrupted(Estimator):
    """An estimator during which the user presses Ctrl-C."""

    name = "interrupted"

    def estimate(self, problem):
        raise KeyboardInterrupt


@pytest.fixture
def extra_plugin(monkeypatch):
    """The installed plugins plus ``kaput``, ``refuses`` and ``interrupted`` from the
    distribution ``buggy-estimators``."""
    module = types.ModuleType("buggy")

    @hookimpl
    def symfuse_register_stages(registry):
        for cls in (Kaput, Refuses, Interrupted):
            registry.add(cls)

    module.symfuse_register_stages = symfuse_register_stages

    def load_registry():
        manager = PluginManager()
        manager.load_entry_points()
        manager.register(module, Origin("buggy", "buggy-estimators", "0.3"))
        return manager.build_registry()

    monkeypatch.setattr("pipeline.registry.load_registry", load_registry)


# ------------------------------------------------------------------ the output folder


def test_a_non_empty_out_is_refused_and_left_untouched(recording, tmp_path, run):
    out = tmp_path / "earlier"
    out.mkdir()
    (out / "config.toml").write_text("# an earlier run\n")
    code, _, err = run(*fuse_args(recording, out))
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err) == (
        f"symfuse: error: --out {out}: the folder exists and is not empty; pass --overwrite "
        "to replace it, or choose another --out"
    )
    assert [p.name for p in out.iterdir()] == ["config.toml"]
    assert (out / "config.toml").read_text() == "# an earlier run\n"
    assert leftovers(tmp_path) == []


def test_overwrite_replaces_the_folder_whole(recording, tmp_path, run):
    """A PS run into a folder that held a VC run keeps no vc_scores.png."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "result.json").write_text('{"symfuse": "0.1.0", "status": "converged"}')
    (out / "vc_scores.png").write_bytes(b"old")
    code, _, err = run(*fuse_args(recording, out, "--overwrite"))
    assert code == 0, err
    names = {p.name for p in out.iterdir()}
    assert "vc_scores.png" not in names
    assert {"result.json", "config.toml", "completed_stage2.ply"} <= names
    assert leftovers(tmp_path) == []


def test_overwrite_never_deletes_the_runs_own_inputs(recording, tmp_path, run):
    """`fuse --out RUN --overwrite` on RUN's own cloud would delete it with the folder."""
    folder, _, plane = recording
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    for name in ("cloud.ply", "contacts.json"):
        (run_dir / name).write_bytes((folder / name).read_bytes())
    code, _, err = run("fuse", "--cloud", run_dir / "cloud.ply", "--contacts",
                       run_dir / "contacts.json", f"--plane={plane}", "--overwrite",
                       "--out", run_dir)  # fmt: skip
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err) == (
        f"symfuse: error: --out {run_dir}: holds the input {run_dir / 'cloud.ply'}, which "
        "replacing it would delete; choose another --out"
    )
    assert {p.name for p in run_dir.iterdir()} == {"cloud.ply", "contacts.json"}


@pytest.mark.parametrize("verb", ["fuse", "trial", "sweep"])
@pytest.mark.parametrize(
    "result",
    [None, "not json", '{"status": "converged"}'],
    ids=["no-result", "unreadable-result", "result-of-another-tool"],
)
def test_overwrite_never_replaces_a_folder_symfuse_did_not_write(
    recording, tmp_path, run, verb, result
):
    """A project folder given as --out by mistake keeps every file, --overwrite or not."""
    out = tmp_path / "project"
    (out / ".git").mkdir(parents=True)
    (out / "README.md").write_text("mine")
    if result is not None:
        (out / "result.json").write_text(result)
    before = sorted(p.name for p in out.iterdir())
    code, _, err = run(*writing(verb, recording, out)[:-2], "--overwrite", "--out", out)
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err) == (
        f"symfuse: error: --out {out}: the folder holds no earlier symfuse run, and "
        "--overwrite replaces only those; choose another --out"
    )
    assert sorted(p.name for p in out.iterdir()) == before
    assert (out / "README.md").read_text() == "mine"
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("verb", ["fuse", "trial", "sweep"])
def test_out_naming_a_file_is_one_line(recording, tmp_path, run, verb):
    target = tmp_path / "notes.txt"
    target.write_text("keep me")
    argv = writing(verb, recording, target)
    code, _, err = run(*argv)
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err) == f"symfuse: error: --out {target}: exists and is not a folder"
    assert target.read_text() == "keep me"
    code, _, err = run(*argv[:-1], target / "below")
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err).endswith(f"{target} is not a folder")


@pytest.mark.parametrize("verb", ["fuse", "trial", "sweep"])
def test_out_in_a_read_only_folder_is_one_line(recording, tmp_path, run, verb):
    with read_only(tmp_path / "locked") as locked:
        out = locked / "run"
        code, _, err = run(*writing(verb, recording, out))
        assert code == EXIT_BAD_INPUT
        line = one_error_line(err)
        assert line.startswith(f"symfuse: error: --out {out}: cannot ")
        assert list(locked.iterdir()) == []


def test_a_run_failing_before_any_result_leaves_nothing(recording, tmp_path, run):
    folder, _, plane = recording
    (tmp_path / "bad.json").write_text('{"units": "m", "grasps": []}')
    out = tmp_path / "run"
    code, _, err = run("fuse", "--cloud", folder / "cloud.ply", "--contacts",
                       tmp_path / "bad.json", f"--plane={plane}", "--out", out)  # fmt: skip
    assert code == EXIT_BAD_INPUT
    one_error_line(err)
    assert not out.exists()
    assert leftovers(tmp_path) == []


def test_a_trial_failing_before_any_result_leaves_nothing(tmp_path, run):
    out = tmp_path / "run"
    code, _, err = run("trial", "--object", "teapot", "--out", out)
    assert code == EXIT_BAD_INPUT
    assert "teapot" in one_error_line(err)
    assert not out.exists() and leftovers(tmp_path) == []


@pytest.mark.slow
def test_without_out_every_trial_gets_a_fresh_folder(tmp_path, run, monkeypatch):
    """The README's command typed twice: two folders, the first untouched."""
    monkeypatch.chdir(tmp_path)
    for _ in range(2):
        code, out, err = run("trial", "--set", "trial.pictures=false")
        assert code == 0, err
    first, second = Path("runs/trial-cd_drive-seed0"), Path("runs/trial-cd_drive-seed0-2")
    assert f"wrote {second}/" in out
    for folder in (first, second):
        assert json.loads((folder / "result.json").read_text())["status"] == "converged"
    assert leftovers(Path("runs")) == []


def test_fresh_folder_counts_up(tmp_path):
    assert fresh_folder(tmp_path / "a") == tmp_path / "a"
    (tmp_path / "a").mkdir()
    (tmp_path / "a-2").mkdir()
    assert fresh_folder(tmp_path / "a") == tmp_path / "a-3"


def test_staged_output_keeps_a_failed_run_that_wrote_its_result(tmp_path):
    target = tmp_path / "run"
    with pytest.raises(StageFailure), staged_output(target) as staging:
        (staging / "result.json").write_text("{}")
        raise StageFailure("late")
    assert (target / "result.json").is_file()
    with pytest.raises(KeyboardInterrupt), staged_output(tmp_path / "other") as staging:
        (staging / "config.toml").write_text("")
        raise KeyboardInterrupt
    assert not (tmp_path / "other").exists()
    assert leftovers(tmp_path) == []


# ------------------------------------------------------------------ exit codes


def test_a_plugin_that_raises_exits_4_naming_stage_plugin_and_distribution(
    recording, tmp_path, run, extra_plugin
):
    out = tmp_path / "run"
    code, _, err = run(*fuse_args(recording, out, "--set", "estimator.use=kaput"))
    assert code == EXIT_PLUGIN_RAISED
    assert one_error_line(err) == (
        "symfuse: error: estimator 'kaput' (plugin 'buggy' from distribution "
        "'buggy-estimators 0.3') failed in estimate: ZeroDivisionError: division by zero"
    )
    assert not out.exists() and leftovers(tmp_path) == []
    with pytest.raises(PluginRaised) as raised:  # --debug: the traceback, cause chained
        run("--debug", *fuse_args(recording, out, "--set", "estimator.use=kaput"))
    assert isinstance(raised.value.__cause__, ZeroDivisionError)


def test_a_stage_failure_exits_3_and_writes_result_json(recording, tmp_path, run, extra_plugin):
    out = tmp_path / "run"
    code, _, err = run(*fuse_args(recording, out, "--set", "estimator.use=refuses"))
    assert code == EXIT_ESTIMATE_FAILED
    assert one_error_line(err) == (
        "symfuse: error: estimator 'refuses': too few points in the gates"
    )
    document = json.loads((out / "result.json").read_text())
    assert document["status"] == "failed"
    assert document["reason"] == "estimator 'refuses': too few points in the gates"
    assert (out / "config.toml").is_file()


def test_interrupt_exits_130_and_leaves_nothing(recording, tmp_path, run, extra_plugin):
    out = tmp_path / "run"
    code, _, err = run(*fuse_args(recording, out, "--set", "estimator.use=interrupted"))
    assert code == EXIT_INTERRUPTED
    assert err.strip() == "symfuse: interrupted"
    assert not out.exists() and leftovers(tmp_path) == []


def test_plane_with_a_negative_first_number_parses(recording, tmp_path, run):
    folder, _, _ = recording
    cloud, contacts = folder / "cloud.ply", folder / "contacts.json"
    code, _, err = run("fuse", "--cloud", cloud, "--contacts", contacts,
                       "--plane", "-1,0,-0.5", "--out", tmp_path / "a")  # fmt: skip
    assert code == 0, err
    plane = json.loads((tmp_path / "a" / "result.json").read_text())["init"]["plane"]
    assert plane["normal"] == pytest.approx([-1.0, 0.0], abs=1e-12)
    assert plane["offset"] == pytest.approx(-0.5)


# ------------------------------------------------------------------ units


def test_a_cloud_in_millimetres_is_refused_with_a_hint_and_converted_with_units(
    recording, tmp_path, run
):
    folder, case, plane = recording
    np.save(tmp_path / "cloud_mm.npy", 1000.0 * case.cloud.points)
    argv = ["fuse", "--cloud", tmp_path / "cloud_mm.npy", "--contacts", folder / "contacts.json",
            f"--plane={plane}"]  # fmt: skip
    code, _, err = run(*argv, "--out", tmp_path / "a")
    assert code == EXIT_BAD_INPUT
    line = one_error_line(err)
    assert line.startswith(f"symfuse: error: {tmp_path / 'cloud_mm.npy'}: a point lies ")
    assert line.endswith("m from the robot base: looks like millimetres: pass --units mm")
    assert not (tmp_path / "a").exists()
    # --units mm on the cloud in mm; contacts in mm must say so themselves
    contacts = json.loads((folder / "contacts.json").read_text())
    for taxel in contacts["grasps"][0]["taxels"]:
        taxel["position"] = [1000.0 * v for v in taxel["position"]]
    (tmp_path / "contacts_mm.json").write_text(json.dumps(contacts))
    nx, ny, d = (float(v) for v in plane.split(","))
    code, _, err = run("fuse", "--cloud", tmp_path / "cloud_mm.npy", "--contacts",
                       tmp_path / "contacts_mm.json", f"--plane={nx},{ny},{d}", "--units", "mm",
                       "--out", tmp_path / "mm")  # fmt: skip
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err) == (
        f'symfuse: error: {tmp_path / "contacts_mm.json"}: the file says units "m", --units '
        "says mm: drop --units or correct the file"
    )
    contacts["units"] = "mm"
    (tmp_path / "contacts_mm.json").write_text(json.dumps(contacts))
    code, _, err = run("fuse", "--cloud", tmp_path / "cloud_mm.npy", "--contacts",
                       tmp_path / "contacts_mm.json", f"--plane={nx},{ny},{d}", "--units", "mm",
                       "--out", tmp_path / "mm")  # fmt: skip
    assert code == 0, err
    code, _, err = run(*fuse_args(recording, tmp_path / "m"))
    assert code == 0, err
    in_mm = json.loads((tmp_path / "mm" / "result.json").read_text())["stages"][2]
    in_m = json.loads((tmp_path / "m" / "result.json").read_text())["stages"][2]
    assert in_mm["plane"]["offset"] == pytest.approx(in_m["plane"]["offset"], abs=1e-6)
    assert in_mm["bias"]["translation"] == pytest.approx(in_m["bias"]["translation"], abs=1e-6)


def test_taxels_in_millimetres_are_refused_or_read_by_their_declared_units(
    recording, tmp_path, run
):
    folder, _, plane = recording
    contacts = json.loads((folder / "contacts.json").read_text())
    for taxel in contacts["grasps"][0]["taxels"]:
        taxel["position"] = [1000.0 * v for v in taxel["position"]]
    (tmp_path / "c.json").write_text(json.dumps(contacts))
    argv = ["fuse", "--cloud", folder / "cloud.ply", "--contacts", tmp_path / "c.json",
            f"--plane={plane}"]  # fmt: skip
    code, _, err = run(*argv, "--out", tmp_path / "a")
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err).endswith('looks like millimetres: set the file\'s "units" to "mm"')
    assert "grasps[0].taxels" in err
    contacts["units"] = "mm"  # declared: converted without --units
    (tmp_path / "c.json").write_text(json.dumps(contacts))
    code, _, err = run(*argv, "--out", tmp_path / "b")
    assert code == 0, err


def test_a_mesh_in_millimetres_is_refused_and_scaled_with_units(tmp_path, run):
    trimesh.creation.box((45.0, 120.0, 100.0)).export(tmp_path / "brick_mm.stl")
    code, _, err = run("trial", "--mesh", tmp_path / "brick_mm.stl", "--out", tmp_path / "a")
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err) == (
        f"symfuse: error: {tmp_path / 'brick_mm.stl'}: the object is 120 m across: "
        "looks like millimetres: pass --units mm"
    )
    assert not (tmp_path / "a").exists()
    brick = load_object(tmp_path / "brick_mm.stl", units="mm")
    assert sorted(brick.mesh.extents) == pytest.approx([0.045, 0.100, 0.120])
    # A URDF states its scale itself: the hint says where.
    (tmp_path / "brick.urdf").write_text(
        '<robot name="brick"><link name="base"><visual><geometry>'
        '<mesh filename="brick_mm.stl"/></geometry></visual></link></robot>'
    )
    code, _, err = run("trial", "--mesh", tmp_path / "brick.urdf", "--out", tmp_path / "b")
    assert code == EXIT_BAD_INPUT
    assert one_error_line(err).endswith(
        'looks like millimetres: give its meshes scale="0.001 0.001 0.001"'
    )


# ------------------------------------------------------------------ plugins --params


def test_plugins_params_shows_the_effective_defaults(run):
    code, out, _ = run("plugins", "--params")
    assert code == 0
    section = out.split("[sensor.pybullet-kinect]")[1].split("\n[")[0]
    assert "  calibration_yaw_deg = 1.0  (float)" in section
    assert "  calibration_translation_m = (0.004, -0.003, 0.0)" in section


def test_stage_times_add_up_to_the_estimators(recording):
    from pipeline.registry import load_registry

    _, case, _ = recording
    estimator = load_registry().create("estimator", "iekf")
    problem = case.problem  # renders the case's depth view: not the estimator's time
    started = time.perf_counter()
    result = estimator.estimate(problem)
    total = time.perf_counter() - started
    seconds = [stage.seconds for stage in result.stages]
    assert all(s >= 0.0 for s in seconds)
    assert sum(seconds) <= total
    assert sum(seconds) > 0.9 * total
    assert seconds[0] < 0.5 * (seconds[1] + seconds[2])  # Stage 0 is the setup only
