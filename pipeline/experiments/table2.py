"""Paper Table 2: plastic case (44 mm thick), PG-70, thickness per stage with PS and VC.

Five poses (object yaw -30..30 deg around the reference view, where the camera sees the
case's broad face squarely) per initialiser, ``repeats`` seeds each (default 1: the paper's
five runs). ``quick`` keeps one pose per initialiser.
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

NAME = "table2"
DESCRIPTION = (
    "plastic case, PG-70: thickness per stage with PS and VC initialisation (paper Table 2)"
)

STUDY = MeasureStudy(
    name=NAME,
    title="Table 2: plastic case, PG-70",
    measure="thickness",
    true_mm=44.0,
    paper_error_pct={"ps": (11.9, 3.4), "vc": (35.8, 3.5)},
    target_pct=3.4,
)


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    offsets = (QUICK_VIEW_OFFSET_DEG,) if options.quick else VIEW_OFFSETS_DEG
    return object_tasks(options, "plastic_case", inits=("ps", "vc"), view_offsets_deg=offsets)


def run_one(params: dict) -> dict[str, Any]:
    return run_paper_trial(params)


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    return report_measure(rows, out_dir, STUDY)
