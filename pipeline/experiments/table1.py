"""Paper Table 1: CD drive (42 mm thick), PG-70, thickness per stage with PS and VC.

Five poses (object yaw -30..30 deg around the reference view, where the camera sees the
drive's broad face squarely) per initialiser, ``repeats`` seeds each (default 1: the paper's
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

NAME = "table1"
DESCRIPTION = "CD drive, PG-70: thickness per stage with PS and VC initialisation (paper Table 1)"

STUDY = MeasureStudy(
    name=NAME,
    title="Table 1: CD drive, PG-70",
    measure="thickness",
    true_mm=42.0,
    paper_error_pct={"ps": (11.3, 1.9), "vc": (37.6, 1.4)},
    target_pct=1.9,
)


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    offsets = (QUICK_VIEW_OFFSET_DEG,) if options.quick else VIEW_OFFSETS_DEG
    return object_tasks(options, "cd_drive", inits=("ps", "vc"), view_offsets_deg=offsets)


def run_one(params: dict) -> dict[str, Any]:
    return run_paper_trial(params)


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    return report_measure(rows, out_dir, STUDY)
