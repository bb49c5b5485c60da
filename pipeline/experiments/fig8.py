"""Paper Fig. 8: parallel-jaw gripper, diameter error over the initial symmetry error.

Grid: tactile angles 0, +-45, +-90 deg x theta 0..90 deg (11.25 deg steps) x r -50..50 mm
(10 mm steps), zero bias, one trial per cell unless ``repeats`` says otherwise (5 x 9 x 11 =
495 trials). ``quick`` keeps theta {0, 45} and r {-20, +20}.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from . import ExperimentOptions, SweepTask
from .synthetic_study import CONFIG_SECTIONS as CONFIG_SECTIONS
from .synthetic_study import R_MM_FULL, THETA_DEG_FULL, grid_tasks, report_grid, run_trial

NAME = "fig8"
DESCRIPTION = "synthetic cylinder, parallel jaw: diameter error vs symmetry error (paper Fig. 8)"

TACTILE_ANGLES_DEG = (0.0, 45.0, -45.0, 90.0, -90.0)
CLAIMS = (
    "tactile angle 0: diameter error < 4 mm for theta up to 45 deg and |r| <= 30 mm",
    "tactile angle +-45: more sensitive to the initialisation",
    "tactile angle +-90 (grasped from the sides): large errors in r are not corrected",
)


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    thetas = (0.0, 45.0) if options.quick else THETA_DEG_FULL
    rs = (-20.0, 20.0) if options.quick else R_MM_FULL
    return grid_tasks(
        options,
        gripper="parallel",
        tactile_angles_deg=TACTILE_ANGLES_DEG,
        thetas_deg=thetas,
        rs_mm=rs,
    )


def run_one(params: dict) -> dict[str, Any]:
    return run_trial(params)


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    return report_grid(
        rows, out_dir, name=NAME, title="Fig. 8: parallel jaw, synthetic cylinder", claims=CLAIMS
    )
