"""Reports of the geometric-deviation studies (spray bottle, three-finger set): the
deviation of the completed model from the true surface per stage and group."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.experiments.common import failures_section, fmt
from pipeline.experiments.paper_report import (
    DEVIATION_TARGET_MM,
    SHAPE_HEADER,
    bias_section,
    deviation_box_figure,
    met,
    shape_cells,
    shape_score_section,
)
from pipeline.experiments.paper_trial import DIVERGED_GROWTH_MM
from pipeline.experiments.rows import (
    STAGES,
    count_rows,
    failure_lines,
    finished_rows,
    mean_value,
    value,
)
from pipeline.experiments.sweep import write_csv


def deviation_verdict(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Stage 0/1/2 averaged medians and means of the deviation over finished ``rows`` (mm)
    and whether Stage 2's median is below Stage 0's."""
    finished = finished_rows(rows)
    summary: dict[str, Any] = {}
    for stage in STAGES:
        for field in ("median", "mean"):
            summary[f"stage{stage}_{field}"] = mean_value(
                finished, f"stage{stage}_deviation_{field}_mm"
            )
    summary["improves"] = bool(summary["stage2_median"] < summary["stage0_median"])
    return summary


def report_deviation(
    rows: Sequence[Mapping[str, Any]],
    out_dir: Path,
    *,
    name: str,
    title: str,
    groups: Mapping[str, Sequence[Mapping[str, Any]]],
    figures: Sequence[tuple[str, Sequence[tuple[float, Sequence[Mapping[str, Any]]]], str]],
    paper: Sequence[str],
) -> list[Path]:
    """``results.csv``, deviation box plots and ``report.md`` of a geometric-deviation study.

    Args:
        groups: label -> rows; the targets are checked per group (an object, or an
            object with one initialiser): Stage 2 median deviation below Stage 0's, and the
            mean deviation after fusion averaged over all groups <= 5 mm.
        figures: (file stem, categories, x label) per figure; categories are (position,
            rows) pairs for :func:`deviation_box_figure`.
        paper: the paper's statements, quoted in the report.
    """
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    lines = [f"# {title}", "", "Paper:", "", *[f"- {claim}" for claim in paper], ""]
    lines += [
        "Ours: deviation of every completed point from the true surface (mm), per trial "
        "summarised as min/q1/median/q3/max/mean; below, averaged over a group's finished "
        "trials.",
        "",
        "| group | trials | median S0 / S1 / S2 | mean S0 / S1 / S2 | S2 median < S0 |",
        "|---|---|---|---|---|",
    ]
    verdicts = {}
    for label, group in groups.items():
        summary = deviation_verdict(group)
        verdicts[label] = summary
        medians = " / ".join(fmt(summary[f"stage{k}_median"]) for k in STAGES)
        means = " / ".join(fmt(summary[f"stage{k}_mean"]) for k in STAGES)
        lines.append(
            f"| {label} | {count_rows(group).text()} | {medians} | {means} "
            f"| {'yes' if summary['improves'] else 'NO'} |"
        )
    finals = [v["stage2_mean"] for v in verdicts.values() if math.isfinite(v["stage2_mean"])]
    average = float(np.mean(finals)) if finals else math.nan
    improving = [label for label, v in verdicts.items() if v["improves"]]
    counts = count_rows(rows)
    lines += [
        "",
        f"- Stage 2 median deviation below Stage 0 on every group: "
        f"{met(bool(verdicts) and len(improving) == len(verdicts))} "
        f"({len(improving)}/{len(verdicts)}).",
        f"- Mean deviation after fusion, averaged over the groups: {fmt(average)} mm "
        f"(target <= {DEVIATION_TARGET_MM:g} mm): "
        f"{met(average <= DEVIATION_TARGET_MM)}.",
        f"- Trials: {counts.text()} (diverged: the estimator says so or the median deviation "
        f"grows by more than {DIVERGED_GROWTH_MM:g} mm over Stage 0).",
    ]
    lines += ["", *shape_score_section(groups)]
    lines += bias_section(groups)
    lines += ["", "## Per trial", "", *_deviation_trial_table(rows)]
    paths = []
    for stem, categories, xlabel in figures:
        usable = [(position, finished_rows(group)) for position, group in categories]
        usable = [(position, group) for position, group in usable if group]
        if not usable:
            continue
        path = deviation_box_figure(
            usable, out_dir / f"{stem}.png", xlabel=xlabel, title=f"{title} ({stem})"
        )
        paths.append(path)
        lines += ["", f"![{stem}]({path.name})"]
    lines += failures_section(failure_lines(rows))
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [csv_path, *paths, report_path]


def _deviation_trial_table(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per finished trial: median deviation, plane errors and shape scores per
    stage."""
    header = [
        "trial",
        "median dev. S0 / S1 / S2 (mm)",
        "plane angle err. S0 / S2 (deg)",
        "plane offset err. S0 / S2 (mm)",
        *SHAPE_HEADER,
        "final status",
    ]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in finished_rows(rows):
        medians = " / ".join(fmt(value(row, f"stage{k}_deviation_median_mm")) for k in STAGES)
        angles = " / ".join(fmt(value(row, f"stage{k}_plane_angle_error_deg")) for k in (0, 2))
        offsets = " / ".join(fmt(value(row, f"stage{k}_plane_offset_error_mm")) for k in (0, 2))
        status = str(row.get("status")) + (" (diverged)" if row.get("diverged") else "")
        cells = [str(row.get("key", "?")), medians, angles, offsets, *shape_cells([row]), status]
        lines.append("| " + " | ".join(cells) + " |")
    return lines
