"""Experiments that ``symfuse sweep NAME`` runs: the paper's figures and tables.

:data:`EXPERIMENTS` (:mod:`.definitions`) lists them, one row each. A row's ``tasks`` enumerates
the grid (each task's ``key`` is unique and stable, so a re-run can skip finished ones);
``run_one`` runs a single trial from its JSON parameters and returns one JSON-serialisable
result row; ``report`` turns all rows into the CSV, the figure PNG(s) and ``report.md``.
:mod:`pipeline.experiments.sweep` runs the tasks locally or on Dask.

A trial's config is the sweep's (the defaults, ``--config`` files and ``--set`` values; what
the user changed travels in :attr:`ExperimentOptions.config`) with the experiment's own
per-task settings applied over it; a task lists those in :attr:`SweepTask.settings` and the
sweep's ``report.md`` shows where they replace the user's values.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pipeline.experiments.definitions import EXPERIMENTS, Experiment, experiment_descriptions

__all__ = [
    "EXPERIMENTS",
    "LOCATION_PARAMS",
    "Experiment",
    "ExperimentOptions",
    "SweepTask",
    "experiment_descriptions",
]

#: Task params that say where a trial keeps its files, not what it computes: they are left
#: out of the row hash, so a sweep folder can be moved and resumed.
LOCATION_PARAMS = frozenset({"trial_dir"})


@dataclass(frozen=True)
class SweepTask:
    """One trial of a sweep.

    Attributes:
        key: stable and unique within the sweep.
        params: the JSON params for ``run_one``.
        settings: the config values (``section.key=value``) the experiment sets for this
            task over the sweep's config; for the report.
    """

    key: str
    params: Mapping[str, Any]
    settings: tuple[str, ...] = ()


@dataclass(frozen=True)
class ExperimentOptions:
    """What the user chose on the ``symfuse sweep`` command line.

    Attributes:
        estimator: estimator implementation name (``iekf``, ``icp``, ``mirror-only``, ...).
        estimator_params: its parameters (``[estimator.<name>]`` config values).
        config: the user's config where it differs from the shipped defaults (a sparse
            nested dict of TOML values), every section; experiments pass on what their
            trials read.
        quick: a reduced grid (a few points per axis) for smoke tests and CI.
        grid: the paper's grid instead of randomly drawn cases (the experiments with
            :attr:`~.definitions.Experiment.randomised`).
        seed: base seed; every task derives its own seed from this and its key.
        repeats: trials per grid point where the experiment repeats (None: the paper's).
        out_dir: the sweep's output folder; experiments that run full trials keep each
            trial's files under ``out_dir/trials/<key>/`` (None: trials are not kept).
        scans: a folder of scanned meshes (``*/textured.obj``) for the experiments that
            read one (``READS_SCANS = True`` in their module), or None.
        captures: a folder of labelled recorded captures (``*.pcd``) for the experiments
            that read one (``READS_CAPTURES = True``), or None.
    """

    estimator: str = "iekf"
    estimator_params: Mapping[str, Any] = field(default_factory=dict)
    config: Mapping[str, Any] = field(default_factory=dict)
    quick: bool = False
    grid: bool = False
    seed: int = 0
    repeats: int | None = None
    out_dir: Path | None = None
    scans: Path | None = None
    captures: Path | None = None
