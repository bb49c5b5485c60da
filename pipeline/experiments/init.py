"""Symmetry-initialiser accuracy on the catalogue's objects in full simulated trials.

For the box-like CD drive, the salt cylinder and the spray bottle, seen by the Kinect from
45 deg elevation at 20 random yaws each (uniform over a full turn, seeded), every
initialiser in ``INITS`` proposes its Stage 0 plane in a full PyBullet trial (PS after its
grasp, as the method requires). A plane succeeds when its orientation is within 10 deg and
its offset within 10 mm of the true mirror plane (for the rotational salt cylinder any
vertical plane through its axis is true, so only the offset counts). Stage 0 does not depend
on the estimator, so the trials run the cheap ``mirror-only`` one unless ``--estimator``
says otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.experiments import ExperimentOptions, SweepTask
from pipeline.experiments.common import task_seed
from pipeline.experiments.paper_tasks import paper_task, user_settings
from pipeline.experiments.paper_trial import run_paper_trial
from pipeline.experiments.rows import INIT_LABELS, group_rows
from pipeline.experiments.sweep import write_csv

NAME = "init"
DESCRIPTION = "initialisers (PS, VC, PCA) on the catalogue in PyBullet: plane within 10 deg/10 mm"
OBJECTS = ("cd_drive", "salt_cylinder", "spray_bottle")
INITS = ("ps", "vc", "pca")
YAWS = 20
QUICK_YAWS = 1
ANGLE_TOLERANCE_DEG = 10.0
OFFSET_TOLERANCE_MM = 10.0


def yaws_deg(seed: int, count: int) -> np.ndarray:
    """``count`` object yaws uniform over a full turn, the same for every initialiser."""
    return np.random.default_rng(seed).uniform(-180.0, 180.0, count)


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    count = QUICK_YAWS if options.quick else (options.repeats or YAWS)
    estimator = "mirror-only" if options.estimator == "iekf" else options.estimator
    root = None if options.out_dir is None else Path(options.out_dir) / "trials"
    result = []
    for name in OBJECTS:
        for index, yaw in enumerate(yaws_deg(options.seed, count)):
            for init in INITS:
                key = f"{name}/{init}/yaw{index:02d}"
                result.append(
                    paper_task(
                        key,
                        {
                            "object": name,
                            "init": init,
                            "gripper": "pg70",
                            "yaw_deg": float(yaw),
                            "seed": task_seed(options.seed, f"{name}/yaw{index}"),
                            "overrides": ["trial.pictures=false"],
                            "config": user_settings(options),
                            "estimator": estimator,
                            "estimator_params": (
                                dict(options.estimator_params)
                                if estimator == options.estimator
                                else {}
                            ),
                            "trial_dir": None if root is None else str(root / key),
                        },
                    )
                )
    return result


def run_one(params: dict) -> dict[str, Any]:
    return run_paper_trial(params)


def succeeded(row: Mapping[str, Any]) -> bool:
    """Stage 0 plane within the tolerances (a failed trial counts as a miss)."""
    if row.get("failed") or "error" in row:
        return False
    offset = row.get("stage0_plane_offset_error_mm")
    angle = row.get("stage0_plane_angle_error_deg", 0.0)
    return (
        offset is not None
        and offset <= OFFSET_TOLERANCE_MM
        and angle is not None
        and angle <= ANGLE_TOLERANCE_DEG
    )


def _median(rows: Sequence[Mapping[str, Any]], key: str) -> str:
    values = [row[key] for row in rows if row.get(key) is not None]
    return f"{np.median(values):.1f}" if values else "-"


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv`` and ``report.md``: success rate and median errors per object and
    initialiser."""
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    lines = [
        "# Symmetry initialisation on the catalogue (PyBullet, Kinect at 45 deg elevation)",
        "",
        f"A Stage 0 plane succeeds within {ANGLE_TOLERANCE_DEG:g} deg and "
        f"{OFFSET_TOLERANCE_MM:g} mm of the true mirror plane (offset only for the "
        "rotational salt cylinder). Failed trials (refused grasp, empty segmentation) count "
        "as misses.",
        "",
        "| object | init | success | failed trials | median angle error (deg) "
        "| median offset error (mm) |",
        "|---|---|---|---|---|---|",
    ]
    for (name, init), group in sorted(
        group_rows(rows, lambda r: (r["params"]["object"], r["params"]["init"])).items()
    ):
        hits = sum(succeeded(row) for row in group)
        failed = sum(bool(row.get("failed")) or "error" in row for row in group)
        lines.append(
            f"| {name} | {INIT_LABELS.get(init, init)} | {hits}/{len(group)} | {failed} "
            f"| {_median(group, 'stage0_plane_angle_error_deg')} "
            f"| {_median(group, 'stage0_plane_offset_error_mm')} |"
        )
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n")
    return [csv_path, report_path]
