"""`symfuse sweep`: the whole config reaches the trials, rows are reused only for the same
config, the output folder is resumed or refused, and report.md says what was set."""

from __future__ import annotations

import json

import pytest

from pipeline.errors import EXIT_BAD_INPUT
from pipeline.experiments import EXPERIMENTS, ExperimentOptions
from pipeline.experiments.paper_tasks import trial_config
from pipeline.experiments.sweep import read_rows, settings_section

QUICK = ["sweep", "fig10", "--quick", "--workers", "1"]


def test_a_synthetic_sweep_refuses_settings_its_trials_do_not_read(tmp_path, run):
    out = tmp_path / "sweep"
    code, _, err = run(*QUICK, "--set", "sensor.pybullet-kinect.calibration_yaw_deg=2",
                       "--out", out)  # fmt: skip
    assert code == EXIT_BAD_INPUT
    assert err.strip() == (
        "symfuse: error: sweep fig10: its trials read only [estimator] of the config, not "
        "[sensor]; remove those from --config/--set"
    )
    assert not out.exists()


def test_a_set_to_the_default_in_a_section_a_sweep_does_not_read_is_refused(tmp_path, run):
    out = tmp_path / "sweep"
    code, _, err = run(*QUICK, "--set", "planner.use=top-parallel", "--out", out)
    assert code == EXIT_BAD_INPUT
    assert "its trials read only [estimator] of the config, not [planner]" in err
    assert not out.exists()


def test_grid_is_refused_by_an_experiment_without_random_cases(tmp_path, run):
    out = tmp_path / "sweep"
    code, _, err = run("sweep", "table1", "--grid", "--workers", "1", "--out", out)
    assert code == EXIT_BAD_INPUT
    assert err.strip() == "symfuse: error: sweep table1: --grid applies to fig10, fig8, fig9 only"
    assert not out.exists()


def test_parameters_a_stage_refuses_together_stop_the_sweep_before_any_trial(tmp_path, run):
    out = tmp_path / "sweep"
    threshold = "tactile.pybullet-taxels.contact_threshold_m=0.01"
    code, _, err = run("sweep", "table2", "--workers", "1", "--set", threshold, "--out", out)
    assert code == EXIT_BAD_INPUT
    assert err.strip() == (
        "symfuse: error: config key 'tactile.pybullet-taxels.ray_length_m' (0.005) must be "
        ">= contact_threshold_m (0.01)"
    )
    assert not out.exists()


@pytest.mark.slow
def test_rows_are_reused_only_when_made_with_the_same_config(tmp_path, run):
    out = tmp_path / "sweep"
    code, _, err = run(*QUICK, "--out", out)
    assert code == 0, err
    first = read_rows(out / "results.jsonl")
    assert len(first) == 8 and all(row["config_hash"] for row in first)

    code, _, err = run(*QUICK, "--out", out)  # resumed: nothing re-run
    assert code == 0, err
    assert read_rows(out / "results.jsonl") == first

    changed = ["--set", "estimator.iekf.max_iterations=7"]
    code, _, err = run(*QUICK, *changed, "--out", out)
    assert code == EXIT_BAD_INPUT
    assert err.strip() == (
        f"symfuse: error: {out / 'results.jsonl'}: 8 of 8 finished rows were made with other "
        f"params or config (first: {first[0]['key']}); pass --overwrite to re-run them"
    )
    code, _, err = run(*QUICK, *changed, "--overwrite", "--out", out)
    assert code == 0, err
    rerun = read_rows(out / "results.jsonl")
    assert len(rerun) == 8
    assert all(row["params"]["estimator_params"]["max_iterations"] == 7 for row in rerun)
    assert {row["config_hash"] for row in rerun}.isdisjoint(row["config_hash"] for row in first)
    assert "max_iterations = 7" in (out / "config.toml").read_text()
    report = (out / "report.md").read_text()
    assert "## Configuration" in report
    assert "`estimator.iekf.max_iterations = 7`" in report
    assert "The trials read only [estimator]." in report


@pytest.mark.slow
def test_a_folder_of_something_else_is_refused_and_an_earlier_run_replaced(tmp_path, run):
    out = tmp_path / "sweep"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    for extra in ([], ["--overwrite"]):
        code, _, err = run(*QUICK, *extra, "--out", out)
        assert code == EXIT_BAD_INPUT
        assert err.strip() == (
            f"symfuse: error: --out {out}: the folder holds no earlier symfuse run, and "
            "--overwrite replaces only those; choose another --out"
        )
        assert (out / "notes.txt").read_text() == "mine"
    (out / "result.json").write_text('{"symfuse": "0.1.0"}')  # an earlier trial's folder
    code, _, err = run(*QUICK, "--out", out)
    assert code == EXIT_BAD_INPUT
    assert err.strip() == (
        f"symfuse: error: --out {out}: exists, is not empty and holds no sweep "
        "(results.jsonl); pass --overwrite to replace it"
    )
    code, _, err = run(*QUICK, "--overwrite", "--out", out)
    assert code == 0, err
    assert not (out / "notes.txt").exists()
    assert len(read_rows(out / "results.jsonl")) == 8


def test_a_paper_trial_starts_from_the_users_config_and_the_experiment_wins():
    """--set sensor... reaches the trial; the experiment's own pose replaces the user's."""
    user = {
        "sensor": {"pybullet-kinect": {"calibration_yaw_deg": 2.5}},
        "trial": {"yaw_deg": 99.0, "pictures": False},
    }
    tasks = EXPERIMENTS["table1"].tasks(ExperimentOptions(config=user, quick=True))
    for task in tasks:
        config = trial_config(task.params)
        assert config.stage_params("sensor").calibration_yaw_deg == 2.5
        assert config.trial.pictures is False
        assert config.trial.yaw_deg == pytest.approx(task.params["yaw_deg"])
        assert config.trial.yaw_deg != 99.0
    resolved = {"trial": {"yaw_deg": 99.0, "object": "cd_drive"}, "initialiser": {"use": "vc"}}
    section = settings_section(tasks, resolved, user, sections=list(resolved))
    assert "`sensor.pybullet-kinect.calibration_yaw_deg = 2.5`" in section
    yaw_row = next(line for line in section.splitlines() if line.startswith("| `trial.yaw_deg`"))
    assert yaw_row.endswith("| 99.0 |")
    assert json.dumps(tasks[0].params["yaw_deg"]) in yaw_row
    assert "| `trial.object`" not in section  # the experiment's value equals the config's
    assert '| `initialiser.use` | "ps", "vc" | "vc" |' in section
