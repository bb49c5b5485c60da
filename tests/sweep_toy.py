"""Deterministic toy trials for the sweep-engine tests.

A top-level module so that worker processes (spawned locally or by Dask) can import
``run_one`` by reference.
"""

from __future__ import annotations

import os
import random
import time


def run_one(params: dict) -> dict:
    """A deterministic trial: a seeded pseudo-random value plus a nested result.

    ``params``: ``x`` (number), ``seed`` (int); optional ``fail`` (raise ValueError),
    ``die_after_s`` (kill the worker process after sleeping that long, like a segfault),
    ``sleep_s`` (take that long).
    """
    time.sleep(params.get("sleep_s", 0.0))
    if "die_after_s" in params:
        time.sleep(params["die_after_s"])
        os._exit(3)
    if params.get("fail"):
        raise ValueError(f"x={params['x']} is not allowed\nsecond line of detail")
    rng = random.Random(params["seed"])
    draws = [rng.gauss(0.0, 1.0) for _ in range(3)]
    return {"value": params["x"] ** 2, "draws": draws, "stats": {"mean": sum(draws) / 3}}
