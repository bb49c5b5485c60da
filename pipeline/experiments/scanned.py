"""Trials on scanned meshes (e.g. YCB): the trial ``symfuse trial --mesh PATH`` runs."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pipeline.experiments.common import plugin_registry


def scan_trial_params(
    mesh_path: Path,
    *,
    seed: int = 0,
    yaw_deg: float = 0.0,
    estimator: str = "iekf",
    estimator_params: Mapping[str, Any] | None = None,
    trial_dir: Path | None = None,
) -> dict[str, Any]:
    """Task params of one trial on a scanned mesh file (e.g. a YCB ``textured.obj``).

    The trial a user gets from ``symfuse trial --mesh PATH``: the hand whose planner has the
    best feasible grasp (``trial.gripper = "auto"``, docs/method.md §5), the planners' own
    ranked grasp rather than the paper's single rule, and the default config's initialiser,
    with the object at ``yaw_deg`` (degrees about the vertical, frame R).
    """
    from pipeline.config import load_config

    defaults = load_config(plugin_registry())
    return {
        "object": str(mesh_path),
        "init": defaults.choices["initialiser"],
        "gripper": "auto",
        "paper_grasp": False,
        "view_offset_deg": 0.0,
        "yaw_deg": float(yaw_deg),
        "seed": int(seed),
        "overrides": [],
        "estimator": estimator,
        "estimator_params": dict(estimator_params or {}),
        "trial_dir": None if trial_dir is None else str(trial_dir),
    }


#: Environment variable naming a folder of scanned meshes (``*/textured.obj``, e.g. the YCB
#: scans) that the benchmarks and slow tests on real scans use when not given one.
SCANS_ENV = "SYMFUSE_SCANS"


def default_scans_dir() -> Path | None:
    """The folder named by :data:`SCANS_ENV`, None when it is unset."""
    value = os.environ.get(SCANS_ENV, "").strip()
    return Path(value) if value else None
