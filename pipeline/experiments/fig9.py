"""Paper Fig. 9: three fingers 120 deg apart, diameter error over the initial symmetry error.

Grid: tactile angles 0, +-90, 180 deg x theta 0..90 deg (11.25 deg steps) x r -50..50 mm
(10 mm steps), zero bias (4 x 9 x 11 = 396 trials). At 0 the thumb touches the front and two
fingers the back; at 180 two fingers touch the front. ``quick`` keeps theta {0, 45} and
r {-20, +20}.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from . import ExperimentOptions, SweepTask
from .synthetic_study import CONFIG_SECTIONS as CONFIG_SECTIONS
from .synthetic_study import R_MM_FULL, THETA_DEG_FULL, grid_tasks, report_grid, run_trial

NAME = "fig9"
DESCRIPTION = "synthetic cylinder, three fingers: diameter error vs symmetry error (paper Fig. 9)"

TACTILE_ANGLES_DEG = (0.0, 90.0, -90.0, 180.0)
CLAIMS = (
    "tactile angle 180 (two contacts on the front) is the best, less sensitive to theta",
    "tactile angle 0: a large theta may leave a back finger without correspondences",
    "tactile angles +-90 work reasonably well (two fingers still touch front and back)",
)


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    thetas = (0.0, 45.0) if options.quick else THETA_DEG_FULL
    rs = (-20.0, 20.0) if options.quick else R_MM_FULL
    return grid_tasks(
        options,
        gripper="three_finger",
        tactile_angles_deg=TACTILE_ANGLES_DEG,
        thetas_deg=thetas,
        rs_mm=rs,
    )


def run_one(params: dict) -> dict[str, Any]:
    return run_trial(params)


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    return report_grid(
        rows, out_dir, name=NAME, title="Fig. 9: three fingers, synthetic cylinder", claims=CLAIMS
    )
