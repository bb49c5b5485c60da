"""A world built in a kept PyBullet client (reset) gives the same trial as a new client."""

from __future__ import annotations

import json

import pybullet
import pytest

from pipeline.config import load_config
from pipeline.registry import load_registry
from pipeline.run.trial import run_trial
from pipeline.sim import world


def _without_timings(document: dict) -> str:
    """The document as JSON without its wall times (``timings``, every ``seconds``)."""

    def strip(value):
        if isinstance(value, dict):
            return {k: strip(v) for k, v in value.items() if k not in ("timings", "seconds")}
        if isinstance(value, list):
            return [strip(v) for v in value]
        return value

    return json.dumps(strip(document), sort_keys=True)


@pytest.mark.slow
def test_a_reused_client_gives_the_same_trial_as_a_new_one(tmp_path, monkeypatch):
    registry = load_registry()
    config = load_config(registry, overrides=["trial.pictures=false"])
    # Another object, hand and pose first, so the kept client has a history.
    other = load_config(
        registry,
        overrides=["trial.pictures=false", "trial.object=salt_cylinder", "trial.yaw_deg=40"],
    )
    monkeypatch.setenv(world.REUSE_VARIABLE, "0")
    monkeypatch.setattr(world, "_idle_clients", [])
    fresh = run_trial(config, registry, tmp_path / "fresh").document
    assert world._idle_clients == []  # every world disconnected its own client

    monkeypatch.setenv(world.REUSE_VARIABLE, "1")
    run_trial(other, registry, tmp_path / "first")
    (kept,) = world._idle_clients
    reused = run_trial(config, registry, tmp_path / "reused").document
    assert world._idle_clients == [kept]  # the same client served the second trial
    assert pybullet.getNumBodies(physicsClientId=kept) == 0  # released empty
    assert _without_timings(reused) == _without_timings(fresh)
