"""Reports of the Table 1-3 studies: one dimension (thickness or diameter) per stage and
initialiser, ours beside the paper's."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.experiments.common import failures_section, fmt
from pipeline.experiments.definitions import MeasureTable
from pipeline.experiments.paper_report import (
    SHAPE_HEADER,
    bias_section,
    deviation_box_figure,
    met,
    shape_cells,
    shape_score_section,
)
from pipeline.experiments.paper_trial import DIVERGED_GROWTH_MM
from pipeline.experiments.rows import (
    INIT_LABELS,
    STAGES,
    count_rows,
    failure_lines,
    finished_rows,
    group_rows,
    value,
)
from pipeline.experiments.sweep import write_csv
from pipeline.reports.figures import BoxPanel, box_plot_figure

#: "Clearly better than Stage 0": the final error is at most this fraction of Stage 0's.
CLEARLY_BETTER_RATIO = 0.5


def measure_statistics(
    rows: Sequence[Mapping[str, Any]], measure: str, true_mm: float, stage: int
) -> dict[str, float]:
    """Mean and std (mm) of the measured dimension over ``rows`` at ``stage``, the error of
    the mean in percent (the paper's "error %"), and the mean per-trial absolute error (%).
    NaN when no row has the measure."""
    values = np.array([value(row, f"stage{stage}_{measure}_mm") for row in rows])
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return {"mean": math.nan, "std": math.nan, "error_pct": math.nan, "abs_error_pct": math.nan}
    mean = float(np.mean(values))
    return {
        "mean": mean,
        "std": float(np.std(values, ddof=1)) if len(values) > 1 else 0.0,
        "error_pct": abs(mean - true_mm) / true_mm * 100.0,
        "abs_error_pct": float(np.mean(np.abs(values - true_mm))) / true_mm * 100.0,
    }


def _measure_table(rows: Sequence[Mapping[str, Any]], study: MeasureTable, init: str) -> list[str]:
    """The paper-style table of one initialiser: one line per trial, then mean, std, error."""
    with_angle = study.measure == "thickness"
    unit = f"{study.measure.capitalize()} (mm)"
    header = ["trial", "view (deg)", f"{unit} S0", "S1", "S2"]
    if with_angle:
        header += ["Angle (deg) S0", "S1", "S2"]
    header += [*SHAPE_HEADER, "final status"]
    lines = [
        f"### {INIT_LABELS.get(init, init)}-initialisation",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    finished = finished_rows(rows)
    for number, row in enumerate(finished, start=1):
        cells = [str(number), f"{row['params']['view_offset_deg']:+g}"]
        cells += [fmt(value(row, f"stage{k}_{study.measure}_mm"), 2) for k in STAGES]
        if with_angle:
            cells += [fmt(value(row, f"stage{k}_side_angle_deg"), 2) for k in STAGES]
        cells += shape_cells([row])
        cells.append(str(row.get("status")) + (" (diverged)" if row.get("diverged") else ""))
        lines.append("| " + " | ".join(cells) + " |")
    statistics = [measure_statistics(finished, study.measure, study.true_mm, k) for k in STAGES]
    angles = [
        np.array([value(row, f"stage{k}_side_angle_deg") for row in finished]) for k in STAGES
    ]
    no_shape = [""] * len(SHAPE_HEADER)
    blank = [""] * (3 if with_angle else 0) + no_shape + [""]
    for label, field in (("mean", "mean"), ("std. dev.", "std")):
        cells = [label, ""] + [fmt(s[field], 2) for s in statistics]
        if with_angle:
            reduce = np.nanmean if field == "mean" else _nanstd
            cells += [fmt(float(reduce(a)), 2) if np.isfinite(a).any() else "-" for a in angles]
        cells += shape_cells(finished) if field == "mean" else no_shape
        lines.append("| " + " | ".join([*cells, ""]) + " |")
    for label, field in (
        ("error % (of the mean)", "error_pct"),
        ("mean abs. error %", "abs_error_pct"),
    ):
        cells = [label, ""] + [f"{fmt(s[field])} %" for s in statistics] + blank
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _nanstd(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(np.std(finite, ddof=1)) if len(finite) > 1 else 0.0


def report_measure(
    rows: Sequence[Mapping[str, Any]], out_dir: Path, study: MeasureTable
) -> list[Path]:
    """``results.csv``, ``<name>_error.png`` (per-trial error % per stage and init),
    ``<name>_deviation.png`` (deviation boxes per init and stage) and ``report.md`` (the
    paper-style table per init, ours beside the paper's numbers, targets met or missed)."""
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    by_init = group_rows(rows, lambda row: row["params"]["init"])
    lines = [
        f"# {study.title}",
        "",
        f"True {study.measure}: {study.true_mm:g} mm. Every trial is one simulated grasp "
        "(object yaw relative to the reference view in the 'view' column). 'error %' is the "
        "paper's: |mean - true| / true; the mean per-trial absolute error is given too.",
        "",
        "## Ours beside the paper",
        "",
        "| init | trials | S0 error % ours (paper) | S2 error % ours (paper) | S2 mean abs. "
        f"error % | S2 <= {study.target_pct:g} % | S2 <= {CLEARLY_BETTER_RATIO:g} x S0 |",
        "|---|---|---|---|---|---|---|",
    ]
    verdicts = []
    tables: list[str] = []
    for init, group in by_init.items():
        finished = finished_rows(group)
        stage0 = measure_statistics(finished, study.measure, study.true_mm, 0)
        stage2 = measure_statistics(finished, study.measure, study.true_mm, 2)
        paper0, paper2 = study.paper_error_pct.get(init, (math.nan, math.nan))
        accurate = bool(stage2["error_pct"] <= study.target_pct)
        better = bool(stage2["error_pct"] <= CLEARLY_BETTER_RATIO * stage0["error_pct"])
        verdicts.append((accurate, better))
        lines.append(
            f"| {INIT_LABELS.get(init, init)} | {count_rows(group).text()} "
            f"| {fmt(stage0['error_pct'])} ({fmt(paper0)}) | {fmt(stage2['error_pct'])} "
            f"({fmt(paper2)}) | {fmt(stage2['abs_error_pct'])} | {met(accurate)} "
            f"| {met(better)} |"
        )
        tables += ["", *_measure_table(group, study, init)]
    ps_diverged = count_rows(by_init.get("ps", [])).diverged
    labelled = {INIT_LABELS.get(init, init): group for init, group in by_init.items()}
    lines += [
        "",
        f"- Stage 2 error <= {study.target_pct:g} % (paper's after-fusion figure): "
        f"{met(bool(verdicts) and all(a for a, _ in verdicts))} "
        f"({sum(a for a, _ in verdicts)}/{len(verdicts)} initialisers).",
        f"- Stage 2 clearly better than Stage 0 (error at most {CLEARLY_BETTER_RATIO:g} x "
        f"Stage 0's): {met(bool(verdicts) and all(b for _, b in verdicts))} "
        f"({sum(b for _, b in verdicts)}/{len(verdicts)} initialisers).",
        f"- No diverged trial with PS: {met(ps_diverged == 0)} "
        f"({ps_diverged} diverged). A trial diverges when the estimator says so or its median "
        f"deviation grows by more than {DIVERGED_GROWTH_MM:g} mm over Stage 0.",
        "",
        *shape_score_section(labelled),
        *bias_section(labelled),
        "",
        "## Per trial",
        *tables,
    ]
    figures = _measure_figures(by_init, out_dir, study)
    lines += ["", *[f"![{path.stem}]({path.name})" for path in figures]]
    lines += failures_section(failure_lines(rows))
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [csv_path, *figures, report_path]


def _measure_figures(
    by_init: Mapping[str, Sequence[Mapping[str, Any]]], out_dir: Path, study: MeasureTable
) -> list[Path]:
    inits = [init for init, group in by_init.items() if finished_rows(group)]
    if not inits:
        return []
    panels = []
    for init in inits:
        finished = finished_rows(by_init[init])
        samples = []
        for stage in STAGES:
            measured = np.array(
                [value(row, f"stage{stage}_{study.measure}_mm") for row in finished]
            )
            measured = measured[np.isfinite(measured)]
            samples.append(np.abs(measured - study.true_mm) / study.true_mm * 100.0)
        panels.append(
            BoxPanel(f"{INIT_LABELS.get(init, init)}-initialisation", np.array(STAGES), samples)
        )
    error_path = box_plot_figure(
        panels,
        out_dir / f"{study.name}_error.png",
        xlabel="stage",
        ylabel=f"{study.measure} error (%)",
        threshold=study.target_pct,
        title=f"{study.title}: per-trial {study.measure} error",
    )
    categories = [(float(i), finished_rows(by_init[init])) for i, init in enumerate(inits, start=1)]
    labels = ", ".join(
        f"{i} {INIT_LABELS.get(init, init)}" for i, init in enumerate(inits, start=1)
    )
    deviation_path = deviation_box_figure(
        categories,
        out_dir / f"{study.name}_deviation.png",
        xlabel=f"initialisation ({labels})",
        title=f"{study.title}: deviation (mean box over trials)",
    )
    return [error_path, deviation_path]
