"""The third-party example plugin: install it with pip, see it listed, select it by
config, run it, uninstall it and see it gone."""

from __future__ import annotations

import contextlib
import dataclasses
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "symfuse-voxel-segmenter"
DIST = "symfuse-voxel-segmenter"


def pip(*args: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr


def symfuse(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pipeline.cli", *args], capture_output=True, text=True, timeout=120
    )


@contextlib.contextmanager
def installing(example: Path, dist: str) -> Iterator[None]:
    """``example`` pip-installed (without dependencies) for the duration of the block."""
    pip("install", "--no-deps", str(example))
    try:
        yield
    finally:
        pip("uninstall", "-y", dist)


def run_own_tests(example: Path) -> str:
    """Run ``example``'s own tests against the installed symfuse; their pytest summary."""
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(example / "tests")],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def listing_after_uninstalling(example: Path, dist: str) -> str:
    """``symfuse plugins`` after installing ``example`` and uninstalling it again."""
    with installing(example, dist):
        pass
    listing = symfuse("plugins")
    assert listing.returncode == 0, listing.stderr
    return listing.stdout


@pytest.fixture(scope="module")
def installed():
    with installing(EXAMPLE, DIST):
        yield


@pytest.mark.slow
def test_listed_selectable_and_working(installed):
    listing = symfuse("plugins")
    assert listing.returncode == 0, listing.stderr
    row = next(line for line in listing.stdout.splitlines() if " voxel-grid " in line)
    assert row.split()[:4] == ["segmenter", "voxel-grid", DIST, "1.0.0"]

    config = symfuse(
        "config", "--set", "segmenter.use=voxel-grid", "--set", "segmenter.voxel-grid.voxel_m=0.004"
    )
    assert config.returncode == 0, config.stderr
    assert 'use = "voxel-grid"' in config.stdout
    assert "voxel_m = 0.004" in config.stdout

    # the same path the runner takes: registry from entry points, selection by config
    from pipeline.config import load_config
    from pipeline.registry import load_registry
    from pipeline.synthetic import box_object, synthetic_observation

    registry = load_registry()
    chosen = load_config(registry, overrides=["segmenter.use=voxel-grid"])
    segmenter = chosen.create(registry, "segmenter")
    observation = synthetic_observation(box_object(0.042, 0.15, 0.10), (0.0, 0.0, 0.3))
    cloud = segmenter.segment(observation)
    truth = observation.object_mask[cloud.pixels[:, 0], cloud.pixels[:, 1]]
    assert len(cloud) > 1000
    assert truth.mean() > 0.99  # what it keeps is the object
    # and it keeps most of the object's pixels that stand 20 mm above the table
    on_object = observation.object_mask.sum()
    assert len(cloud) > 0.6 * on_object
    assert dataclasses.asdict(segmenter.params)["voxel_m"] == 0.005
    assert np.all(cloud.points[:, 2] > 0.02)


@pytest.mark.slow
def test_uninstalling_removes_it():
    assert "voxel-grid" not in listing_after_uninstalling(EXAMPLE, DIST)
    chosen = symfuse("config", "--set", "segmenter.use=voxel-grid")
    assert chosen.returncode == 2
    assert chosen.stderr.startswith(
        "symfuse: error: config key 'segmenter.use': no segmenter named 'voxel-grid' (available: "
    )
