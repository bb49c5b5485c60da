"""Paper Fig. 10: tolerance to an initial bias error, parallel jaw and three fingers.

Each gripper at its best tactile angle (parallel 0 deg, three fingers 180 deg); bias
magnitudes 0..50 mm in 5 mm steps; per magnitude r in {-15, -7.5, 0, 7.5, 15} mm x theta in
{0, 22.5, 45} deg x 5 random horizontal bias directions = 75 trials (2 x 11 x 75 = 1650).
The directions come from each task's seed and are stored in its params. The paper plots
quartiles and extremes of 75 points per magnitude; so does :func:`report` (every trial is one
point; a trial without a defined diameter counts as a failure with infinite error).
``quick`` keeps magnitudes {0, 15}, r {0}, theta {0} and 2 directions.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..figures import BoxPanel, box_plot_figure
from ..sweep import write_csv
from . import ExperimentOptions, SweepTask
from .common import failures_section, fmt, task_seed
from .synthetic_report import SUCCESS_MM, diagnosis_section, final_error, ok_rows, stage_error
from .synthetic_study import CONFIG_SECTIONS as CONFIG_SECTIONS
from .synthetic_study import run_trial, trial_params

NAME = "fig10"
DESCRIPTION = "synthetic cylinder: diameter error vs initial bias magnitude (paper Fig. 10)"

#: Gripper -> (tactile angle in deg, bias magnitude up to which the paper's median is < 4 mm).
GRIPPERS = {"parallel": (0.0, 15.0), "three_finger": (180.0, 50.0)}
BIAS_MM_FULL = tuple(float(v) for v in np.arange(0.0, 50.01, 5.0))
R_MM = (-15.0, -7.5, 0.0, 7.5, 15.0)
THETA_DEG = (0.0, 22.5, 45.0)
DIRECTIONS = 5


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    magnitudes = (0.0, 15.0) if options.quick else BIAS_MM_FULL
    rs = (0.0,) if options.quick else R_MM
    thetas = (0.0,) if options.quick else THETA_DEG
    directions = options.repeats or (2 if options.quick else DIRECTIONS)
    result = []
    for gripper, (phi, _) in GRIPPERS.items():
        for magnitude in magnitudes:
            for theta in thetas:
                for r in rs:
                    for k in range(directions):
                        key = f"{gripper}/bias{magnitude:g}/theta{theta:g}/r{r:+g}/dir{k}"
                        direction_rng = np.random.default_rng(task_seed(options.seed, key + "/d"))
                        result.append(
                            trial_params(
                                options,
                                key,
                                gripper=gripper,
                                tactile_angle_deg=phi,
                                theta_deg=theta,
                                r_mm=r,
                                bias_mm=magnitude,
                                bias_direction_deg=float(direction_rng.uniform(0.0, 360.0)),
                            )
                        )
    return result


def run_one(params: dict) -> dict[str, Any]:
    return run_trial(params)


def _as_failures_infinite(values: list[float]) -> np.ndarray:
    return np.array([math.inf if math.isnan(v) else v for v in values])


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv``, ``fig10.png`` (box plots per gripper) and ``report.md``."""
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    good, failed = ok_rows(rows)
    lines = [
        "# Fig. 10: tolerance to bias, synthetic cylinder",
        "",
        "Paper: median diameter error < 4 mm up to 15 mm bias with the parallel "
        "jaw (tactile angle 0), up to 50 mm with three fingers (tactile angle 180).",
        "",
        f"Ours: final (Stage 2) diameter error, every trial one point (|r| <= 15 mm, theta <= "
        f"45 deg, random bias directions); a run without a defined diameter counts as "
        f"infinite. 'reach' = largest magnitude up to which the median stays < {SUCCESS_MM:g} mm.",
    ]
    panels = []
    for gripper, (phi, paper_reach) in GRIPPERS.items():
        subset = [row for row in good if row["params"]["gripper"] == gripper]
        if not subset:
            continue
        magnitudes = sorted({row["params"]["bias_mm"] for row in subset})
        samples, reach, still_good = [], None, True
        table = [
            "",
            f"## {gripper.replace('_', ' ')} (tactile angle {phi:+g} deg)",
            "",
            "| bias (mm) | runs | < 4 mm | S0 median | min | q1 | median | q3 | max (mm) |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for magnitude in magnitudes:
            at = [row for row in subset if row["params"]["bias_mm"] == magnitude]
            final = _as_failures_infinite([final_error(row) for row in at])
            stage0 = _as_failures_infinite([stage_error(row, 0) for row in at])
            with np.errstate(invalid="ignore"):  # inf - inf between two failures
                q = np.percentile(final, [0, 25, 50, 75, 100])
            q = np.where(np.isnan(q), math.inf, q)
            still_good = still_good and bool(q[2] < SUCCESS_MM)
            if still_good:
                reach = magnitude
            samples.append(final)
            table.append(
                f"| {magnitude:g} | {len(at)} | {int((final < SUCCESS_MM).sum())} "
                f"| {fmt(float(np.median(stage0)))} | "
                + " | ".join(fmt(float(v)) for v in q)
                + " |"
            )
        lines += table
        lines += [
            "",
            f"Reach: median < {SUCCESS_MM:g} mm up to {fmt(reach, 0)} mm bias "
            f"(paper: {paper_reach:g} mm).",
        ]
        panels.append(
            BoxPanel(
                f"{gripper.replace('_', ' ')}, tactile angle {phi:+g} deg",
                np.array(magnitudes),
                [np.minimum(s, 1e3) for s in samples],
            )
        )
    lines += diagnosis_section(good)
    figure_paths = []
    if panels:
        figure = box_plot_figure(
            panels,
            out_dir / f"{NAME}.png",
            xlabel="bias magnitude (mm)",
            ylabel="diameter error after fusion (mm)",
            threshold=SUCCESS_MM,
            ylim=(0.0, 30.0),
            title="Fig. 10: |r| <= 15 mm, theta <= 45 deg",
        )
        figure_paths.append(figure)
        lines += ["", f"![{NAME}]({figure.name})"]
    lines += failures_section(failed)
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [csv_path, *figure_paths, report_path]
