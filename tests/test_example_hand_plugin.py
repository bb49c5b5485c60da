"""The example hand plugin (a third hand by its URDF, a world offering it, a planner naming
it): install it with pip, see it listed, select its hand by config, run its own tests
(a trial in the analytic world among them), uninstall it and see it gone."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_example_plugin import installing, listing_after_uninstalling, run_own_tests, symfuse

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "symfuse-wide-gripper"
DIST = "symfuse-wide-gripper"


@pytest.fixture(scope="module")
def installed():
    with installing(EXAMPLE, DIST):
        yield


@pytest.mark.slow
def test_listed_and_its_hand_selectable(installed):
    listing = symfuse("plugins")
    assert listing.returncode == 0, listing.stderr
    rows = {tuple(line.split()[:3]) for line in listing.stdout.splitlines()}
    assert ("world", "pybullet-wide", DIST) in rows
    assert ("planner", "wide-parallel", DIST) in rows
    config = symfuse("config", "--set", "world.use=pybullet-wide", "--set", "trial.gripper=wide")
    assert config.returncode == 0, config.stderr
    # Asked for in the default world, the hand's world is named.
    wrong = symfuse("config", "--set", "trial.gripper=wide")
    assert wrong.returncode != 0
    assert wrong.stderr.strip().endswith(
        "world pybullet-wide offers it: --set world.use=pybullet-wide"
    ), wrong.stderr


@pytest.mark.slow
def test_its_own_tests_pass_against_the_installed_symfuse(installed):
    assert "3 passed" in run_own_tests(EXAMPLE)


@pytest.mark.slow
def test_uninstalling_removes_it():
    listing = listing_after_uninstalling(EXAMPLE, DIST)
    assert "pybullet-wide" not in listing and "wide-parallel" not in listing
