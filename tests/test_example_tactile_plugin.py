"""The example tactile-model plugin: install it with pip, see it listed, select it by
config, run its own tests (written with pipeline.testing) and a whole trial in the
analytic world with it, uninstall it and see it gone."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_example_plugin import installing, listing_after_uninstalling, run_own_tests, symfuse

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "symfuse-threshold-taxels"
DIST = "symfuse-threshold-taxels"


@pytest.fixture(scope="module")
def installed():
    with installing(EXAMPLE, DIST):
        yield


@pytest.mark.slow
def test_listed_and_selectable(installed):
    listing = symfuse("plugins")
    assert listing.returncode == 0, listing.stderr
    row = next(line for line in listing.stdout.splitlines() if " threshold-taxels " in line)
    assert row.split()[:4] == ["tactile", "threshold-taxels", DIST, "1.0.0"]
    config = symfuse(
        "config",
        "--set",
        "tactile.use=threshold-taxels",
        "--set",
        "tactile.threshold-taxels.dead_fraction=0.1",
    )
    assert config.returncode == 0, config.stderr
    assert "dead_fraction = 0.1" in config.stdout


@pytest.mark.slow
def test_its_own_tests_pass_against_the_installed_symfuse(installed):
    assert " passed" in run_own_tests(EXAMPLE)


@pytest.mark.slow
def test_a_whole_trial_runs_with_it_in_the_analytic_world(installed, tmp_path):
    from pipeline.config import load_config
    from pipeline.run.trial import run_trial
    from pipeline.testing import AnalyticWorld, registry_with

    registry = registry_with(AnalyticWorld)
    config = load_config(
        registry,
        overrides=[
            "world.use=analytic",
            "trial.gripper=parallel",
            "trial.pictures=false",
            "tactile.use=threshold-taxels",
            "tactile.threshold-taxels.dead_fraction=0.2",
        ],
    )
    record = run_trial(config, registry, tmp_path / "trial")
    assert record.document["stages_used"]["tactile"] == "threshold-taxels"
    document = json.loads((tmp_path / "trial" / "result.json").read_text())
    # Both pads pressed the object; a fifth of their taxels is dead.
    assert 20 <= document["taxels_in_contact"] < 168
    assert document["status"] in ("converged", "max_iterations")


@pytest.mark.slow
def test_uninstalling_removes_it():
    assert "threshold-taxels" not in listing_after_uninstalling(EXAMPLE, DIST)
