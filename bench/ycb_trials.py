"""Whole trials on real scans: does touch ever make a scanned object's model worse?

Run ``python bench/ycb_trials.py --root DIR`` (or set ``SYMFUSE_SCANS=DIR``), DIR holding
scanned meshes as ``*/textured.obj`` (the YCB scans, for instance: non-watertight meshes
with their origin wherever the scanner put it). Each scan goes through the trial
``symfuse trial --mesh DIR/<name>/textured.obj`` runs (the hand chosen by
``trial.gripper = "auto"``, the planners' ranked grasp, the default initialiser), at
``--yaws`` object yaws (default one, yaw 0; more are drawn uniformly, seeded by
``--seed``). ``--workers 2`` runs two trials at a time, ``--only mug`` a subset, ``--out``
keeps the results and trial folders (a re-run resumes).

Prints one row per trial: the hand, the final status, the median deviation of the
completed model from the scan's surface at Stage 0 and Stage 2 and for the stage the
estimator selected (mm, docs/method.md §9), and whether each meets the target: no more
than 0.2 mm worse than Stage 0 (vision alone) and at most 5 mm (the paper's deviation
"when the method's conditions hold"). Trials whose grasp touched nothing or one side only
are counted apart: there is nothing to fuse (the trial fails, docs/method.md §11). The scans
are not exactly mirror-symmetric and their printed shapes are not always convex, so misses
say as much about the objects as about the method.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

from pipeline.experiments import SweepTask
from pipeline.experiments.init import yaws_deg
from pipeline.experiments.paper_report import DEVIATION_TARGET_MM
from pipeline.experiments.paper_trial import run_paper_trial
from pipeline.experiments.scanned import SCANS_ENV, default_scans_dir, scan_trial_params
from pipeline.experiments.sweep import run_sweep
from pipeline.reports.tables import format_table

#: How much worse than Stage 0 a model may be and still count as no worse (mm): the
#: deviation's own spread between repeated renders of one scene.
WORSE_TOLERANCE_MM = 0.2


def scan_paths(root: Path, only: str | None) -> list[Path]:
    paths = sorted(root.glob("*/textured.obj"))
    return [path for path in paths if only is None or only in path.parent.name]


def meets(stage0: float | None, value: float | None) -> bool:
    """No more than :data:`WORSE_TOLERANCE_MM` worse than Stage 0, and within the paper's
    deviation target."""
    if stage0 is None or value is None or math.isnan(stage0) or math.isnan(value):
        return False
    return value <= stage0 + WORSE_TOLERANCE_MM and value <= DEVIATION_TARGET_MM


def _mm(value: float | None) -> str:
    return "-" if value is None or math.isnan(value) else f"{value:.2f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        type=Path,
        default=default_scans_dir(),
        help=f"folder of scans DIR/*/textured.obj (default: ${SCANS_ENV})",
    )
    parser.add_argument("--only", help="run only scans whose folder name contains this")
    parser.add_argument("--yaws", type=int, default=1, help="object yaws per scan (1: yaw 0)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the yaws and trials")
    parser.add_argument("--workers", type=int, default=1, help="trials run at once")
    parser.add_argument("--out", type=Path, help="keep results and trial folders here")
    args = parser.parse_args()
    if args.root is None:
        parser.error(f"give --root DIR or set {SCANS_ENV}")
    paths = scan_paths(args.root, args.only)
    if not paths:
        parser.error(f"no */textured.obj under {args.root}")
    yaws = [0.0] if args.yaws <= 1 else [float(y) for y in yaws_deg(args.seed, args.yaws)]
    with tempfile.TemporaryDirectory(prefix="symfuse-ycb-") as scratch:
        out = args.out or Path(scratch)
        tasks = [
            SweepTask(
                f"{path.parent.name}/yaw{index:02d}",
                scan_trial_params(
                    path,
                    seed=args.seed,
                    yaw_deg=yaw,
                    trial_dir=out / "trials" / path.parent.name / f"yaw{index:02d}",
                ),
            )
            for path in paths
            for index, yaw in enumerate(yaws)
        ]
        rows = run_sweep(tasks, run_paper_trial, out / "results.jsonl", workers=args.workers)
    table, fused, met_stage2, met_selected = [], 0, 0, 0
    for row in rows:
        stage0 = row.get("stage0_deviation_median_mm")
        stage2 = row.get("stage2_deviation_median_mm")
        selected = row.get("selected_stage")
        chosen = None if selected is None else row.get(f"stage{selected}_deviation_median_mm")
        touched = not row.get("failed") and not row.get("error") and row.get("taxels_in_contact")
        status = row.get("error") or (f"failed: {row['failed']}" if row.get("failed") else "")
        if touched:
            fused += 1
            met_stage2 += meets(stage0, stage2)
            met_selected += meets(stage0, chosen)
        table.append(
            [
                row["key"],
                f"{row['params']['yaw_deg']:.0f}",
                row.get("gripper") or "-",
                status or row.get("status", "-"),
                _mm(stage0),
                _mm(stage2),
                "-" if selected is None else str(selected),
                _mm(chosen),
                ("yes" if meets(stage0, stage2) else "no") if touched else "-",
                ("yes" if meets(stage0, chosen) else "no") if touched else "-",
                f"{row.get('seconds', math.nan):.1f}",
            ]
        )
    target = f"<= S0 + {WORSE_TOLERANCE_MM:g}, <= {DEVIATION_TARGET_MM:g} mm"
    header = [
        "trial",
        "yaw °",
        "hand",
        "status",
        "S0 median (mm)",
        "S2 median (mm)",
        "selected",
        "selected median (mm)",
        f"S2 {target}",
        f"selected {target}",
        "seconds",
    ]
    print(format_table(header, table))
    print(
        f"\n{fused}/{len(rows)} trials fused their grasp (pads on opposing sides); of those, "
        f"Stage 2 meets the target in {met_stage2}, the selected stage in {met_selected}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
