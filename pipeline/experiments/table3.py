"""Paper Table 3: salt cylinder (53 mm diameter), PG-70, diameter per stage with PS and VC.

Five poses (object yaw -30..30 deg; the cylinder is rotationally symmetric, so the poses
differ only in the mesh's facets and the sensor noise) per initialiser, ``repeats`` seeds
each (default 1: the paper's five runs). ``quick`` keeps one pose per initialiser.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from . import ExperimentOptions, SweepTask
from .paper_objects import (
    QUICK_VIEW_OFFSET_DEG,
    VIEW_OFFSETS_DEG,
    MeasureStudy,
    object_tasks,
    report_measure,
    run_paper_trial,
)

NAME = "table3"
DESCRIPTION = (
    "salt cylinder, PG-70: diameter per stage with PS and VC initialisation (paper Table 3)"
)

STUDY = MeasureStudy(
    name=NAME,
    title="Table 3: salt cylinder, PG-70",
    measure="diameter",
    true_mm=53.0,
    paper_error_pct={"ps": (14.1, 4.4), "vc": (14.3, 4.6)},
    target_pct=4.4,
)


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    offsets = (QUICK_VIEW_OFFSET_DEG,) if options.quick else VIEW_OFFSETS_DEG
    return object_tasks(options, "salt_cylinder", inits=("ps", "vc"), view_offsets_deg=offsets)


def run_one(params: dict) -> dict[str, Any]:
    return run_paper_trial(params)


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    return report_measure(rows, out_dir, STUDY)
