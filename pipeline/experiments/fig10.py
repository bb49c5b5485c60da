"""Paper Fig. 10: tolerance to an initial bias error, parallel jaw and three fingers.

Bias magnitudes 0..50 mm in 5 mm steps. By default every trial draws its case at random
(:func:`~.synthetic_study.random_tasks`, :data:`RANDOM_DRAWS`): the tactile angle (three
fingers: the full turn, every angle puts pads on both sides of the plane; parallel jaw:
within 45 deg of the view, where one jaw touches the front and one the back), theta in
0..45 deg, r in -15..15 mm and the bias direction over the full turn; ``repeats`` trials
(default :data:`RANDOM_TRIALS`) per magnitude and hand. With ``grid`` the paper's grid: each
gripper at its best tactile angle (parallel 0 deg, three fingers 180 deg); per magnitude r in
{-15, -7.5, 0, 7.5, 15} mm x theta in {0, 22.5, 45} deg x 5 random bias directions = 75
trials (2 x 11 x 75 = 1650). :func:`report` gives per magnitude the quartiles and extremes
(as the paper plots them), the share of trials that fail (final error >= 4 mm, or none) and
the share that fail silently (not flagged by the self-diagnosis), and a map of the failing
share over the bias magnitude and its direction relative to the pads. ``quick`` keeps
magnitudes {0, 15} and 2 trials each (grid: r {0}, theta {0}, 2 directions).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.experiments import ExperimentOptions, SweepTask
from pipeline.experiments.common import failures_section, fmt, task_seed
from pipeline.experiments.sweep import write_csv
from pipeline.experiments.synthetic_report import (
    SUCCESS_MM,
    diagnosis_section,
    failing_share_figure,
    failure_shares,
    final_error,
    ok_rows,
    percent,
    stage_error,
)
from pipeline.experiments.synthetic_study import CONFIG_SECTIONS as CONFIG_SECTIONS
from pipeline.experiments.synthetic_study import Draws, random_tasks, run_trial, trial_params
from pipeline.reports.figures import BoxPanel, GridPanel, box_plot_figure

NAME = "fig10"
DESCRIPTION = "synthetic cylinder: diameter error vs initial bias magnitude (paper Fig. 10)"
#: Cases are drawn at random unless ``symfuse sweep --grid``.
RANDOMISED = True

#: Gripper -> (tactile angle in deg, bias magnitude up to which the paper's median is < 4 mm).
GRIPPERS = {"parallel": (0.0, 15.0), "three_finger": (180.0, 50.0)}
BIAS_MM_FULL = tuple(float(v) for v in np.arange(0.0, 50.01, 5.0))
R_MM = (-15.0, -7.5, 0.0, 7.5, 15.0)
THETA_DEG = (0.0, 22.5, 45.0)
DIRECTIONS = 5
#: Trials per bias magnitude and hand of the randomised study.
RANDOM_TRIALS = 200
#: What the randomised study draws per hand (see the module docstring).
RANDOM_DRAWS = {
    "parallel": Draws(tactile_deg=(-45.0, 45.0), theta_deg=(0.0, 45.0), r_mm=(-15.0, 15.0)),
    "three_finger": Draws(tactile_deg=(0.0, 360.0), theta_deg=(0.0, 45.0), r_mm=(-15.0, 15.0)),
}
#: Pads per hand (the period of the bias direction relative to the pads is 360 / pads).
PADS = {"parallel": 2, "three_finger": 3}
#: Direction bins of the basin map per period.
DIRECTION_BINS = 6


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    magnitudes = (0.0, 15.0) if options.quick else BIAS_MM_FULL
    if not options.grid:
        count = options.repeats or (2 if options.quick else RANDOM_TRIALS)
        return [
            task
            for gripper, draws in RANDOM_DRAWS.items()
            for magnitude in magnitudes
            for task in random_tasks(
                options, gripper=gripper, count=count, draws=draws, bias_mm=magnitude
            )
        ]
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


def _tactile_angles(rows: list[dict]) -> str:
    angles = [row["params"]["tactile_angle_deg"] for row in rows]
    low, high = min(angles), max(angles)
    return f"{low:+g}" if low == high else f"{low:+.0f}..{high:+.0f}"


def basin_panel(gripper: str, rows: list[dict]) -> GridPanel | None:
    """The failing share (%) of ``rows`` over the bias direction relative to the pads
    (``bias_to_pads_deg``, :data:`DIRECTION_BINS` bins per pad spacing) and its magnitude;
    None without a biased row."""
    biased = [row for row in rows if row["params"]["bias_mm"] > 0 and "bias_to_pads_deg" in row]
    if not biased:
        return None
    period = 360.0 / PADS[gripper]
    width = period / DIRECTION_BINS
    centres = -0.5 * period + width * (np.arange(DIRECTION_BINS) + 0.5)
    magnitudes = sorted({row["params"]["bias_mm"] for row in biased})
    failing = np.zeros((len(magnitudes), DIRECTION_BINS))
    counts = np.zeros_like(failing)
    for row in biased:
        i = magnitudes.index(row["params"]["bias_mm"])
        j = min(int((row["bias_to_pads_deg"] + 0.5 * period) // width), DIRECTION_BINS - 1)
        counts[i, j] += 1
        failing[i, j] += not final_error(row) < SUCCESS_MM
    with np.errstate(invalid="ignore"):
        share = 100.0 * failing / counts
    title = f"{gripper.replace('_', ' ')}, tactile angle {_tactile_angles(rows)} deg"
    return GridPanel(title, centres, np.array(magnitudes), share)


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv``, ``fig10.png`` (box plots per gripper), ``fig10_basin.png`` (failing
    share over the bias direction relative to the pads and its magnitude) and
    ``report.md``."""
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
        f"infinite. 'fail' = final error >= {SUCCESS_MM:g} mm or none; 'silent' = failing "
        f"while the final status claims success (not inconsistent, diverged or "
        f"no_correspondence). 'reach' = largest magnitude up to which the median stays "
        f"< {SUCCESS_MM:g} mm.",
    ]
    panels, basins = [], []
    for gripper, (_, paper_reach) in GRIPPERS.items():
        subset = [row for row in good if row["params"]["gripper"] == gripper]
        if not subset:
            continue
        section, panel = _gripper_section(gripper, subset, paper_reach)
        lines += section
        panels.append(panel)
        basin = basin_panel(gripper, subset)
        if basin is not None:
            basins.append(basin)
    lines += diagnosis_section(good)
    figure_paths = _figures(panels, basins, out_dir)
    lines += [
        line
        for path in figure_paths
        for line in ("", f"![{path.stem.replace('_', ' ')}]({path.name})")
    ]
    lines += failures_section(failed)
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [csv_path, *figure_paths, report_path]


def _gripper_section(
    gripper: str, subset: list[dict], paper_reach: float
) -> tuple[list[str], BoxPanel]:
    """One gripper's table (per bias magnitude: runs, failing and silent shares, Stage 0's
    median and the final error's quartiles), its reach, and its box-plot panel."""
    magnitudes = sorted({row["params"]["bias_mm"] for row in subset})
    samples, reach, still_good = [], None, True
    angles = _tactile_angles(subset)
    lines = [
        "",
        f"## {gripper.replace('_', ' ')} (tactile angle {angles} deg)",
        "",
        "| bias (mm) | runs | fail | silent | S0 median | min | q1 | median | q3 | max (mm) |",
        "|---|---|---|---|---|---|---|---|---|---|",
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
        failing, silent = failure_shares(at)
        lines.append(
            f"| {magnitude:g} | {len(at)} | {percent(failing)} | {percent(silent)} "
            f"| {fmt(float(np.median(stage0)))} | " + " | ".join(fmt(float(v)) for v in q) + " |"
        )
    lines += [
        "",
        f"Reach: median < {SUCCESS_MM:g} mm up to {fmt(reach, 0)} mm bias "
        f"(paper: {paper_reach:g} mm).",
    ]
    panel = BoxPanel(
        f"{gripper.replace('_', ' ')}, tactile angle {angles} deg",
        np.array(magnitudes),
        [np.minimum(s, 1e3) for s in samples],
    )
    return lines, panel


def _figures(panels: list[BoxPanel], basins: list[GridPanel], out_dir: Path) -> list[Path]:
    """``fig10.png`` (the box plots) and ``fig10_basin.png`` (the basin maps), where there
    is something to draw."""
    paths = []
    if panels:
        paths.append(
            box_plot_figure(
                panels,
                out_dir / f"{NAME}.png",
                xlabel="bias magnitude (mm)",
                ylabel="diameter error after fusion (mm)",
                threshold=SUCCESS_MM,
                ylim=(0.0, 30.0),
                title="Fig. 10: |r| <= 15 mm, theta <= 45 deg",
            )
        )
    if basins:
        paths.append(
            failing_share_figure(
                basins,
                out_dir / f"{NAME}_basin.png",
                xlabel="bias direction from the nearest pad (deg; 0: toward it)",
                ylabel="bias magnitude (mm)",
                title="Fig. 10: where the bias's basin ends",
            )
        )
    return paths
