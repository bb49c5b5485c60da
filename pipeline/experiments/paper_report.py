"""Report parts every paper experiment shares: the shape-score table and the deviation
box plots."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.experiments.common import fmt
from pipeline.experiments.rows import (
    STAGES,
    count_rows,
    finished_rows,
    mean_five_numbers,
    mean_value,
)
from pipeline.reports.figures import BoxPanel, box_plot_figure

#: The paper's average deviation after fusion "when the method's conditions hold" (mm).
DEVIATION_TARGET_MM = 5.0


def chi_square_4_quantile(probability: float) -> float:
    """The ``probability`` quantile (0 < probability < 1) of the chi-square distribution
    with 4 degrees of freedom, from its tail beyond ``x = 2 y`` in closed form,
    ``exp(-y) (1 + y)``: Newton's method on the tail's logarithm, concave and falling in
    ``y``, from ``2 - 2 log(tail)`` above the root, so every step stays above it and the
    steps shrink to the root (no scipy import for a report)."""
    log_tail = math.log1p(-probability)
    y = 2.0 - 2.0 * log_tail
    for _ in range(100):
        step = (math.log1p(y) - y - log_tail) * (1.0 + y) / y
        y += step
        if -step <= 1e-15 * y:
            break
    return 2.0 * y


#: The 99 % quantile of the chi-square distribution with 4 degrees of freedom: the bound a
#: truthful covariance keeps a stage's ``bias_nees`` (the normalised error of the four bias
#: components, :func:`pipeline.metrics.evaluation.bias_errors`) under 99 % of the time.
BIAS_NEES_BOUND = chi_square_4_quantile(0.99)


#: The shape scores the reports show per stage: (row field after ``stage{k}_``, column
#: label, decimals). See :func:`pipeline.metrics.evaluation.shape_scores`.
SHAPE_SCORES = (
    ("chamfer_mm", "Chamfer (mm)", 1),
    ("fscore_2mm", "F@2mm", 2),
    ("fscore_5mm", "F@5mm", 2),
    ("iou", "IoU", 2),
)


#: Per-trial table columns of the shape scores.
SHAPE_HEADER = [f"{label} S0 / S1 / S2" for _, label, _ in SHAPE_SCORES]


def deviation_box_figure(
    categories: Sequence[tuple[float, Sequence[Mapping[str, Any]]]],
    out_path: Path,
    *,
    xlabel: str,
    title: str,
) -> Path:
    """Deviation box-and-whisker plots, one panel per stage, one box per category.

    Each box is the category's averaged five-number summary (:func:`mean_five_numbers`).
    It is drawn by handing :func:`pipeline.reports.figures.box_plot_figure` those five values as the
    sample: their 0/25/50/75/100th percentiles (linear interpolation) are exactly the five
    values, so the drawn box is the summary itself.
    """
    panels = []
    for stage in STAGES:
        panels.append(
            BoxPanel(
                f"Stage {stage}",
                np.array([position for position, _ in categories], dtype=np.float64),
                [mean_five_numbers(group, stage) for _, group in categories],
            )
        )
    return box_plot_figure(
        panels,
        out_path,
        xlabel=xlabel,
        ylabel="deviation from the true surface (mm)",
        threshold=DEVIATION_TARGET_MM,
        ylim=(0.0, 40.0),
        title=title,
    )


def shape_cells(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """One ``S0 / S1 / S2`` cell per shape score, each stage's mean over ``rows`` (one row:
    that trial's scores)."""
    return [
        " / ".join(fmt(mean_value(rows, f"stage{k}_{field}"), digits) for k in STAGES)
        for field, _, digits in SHAPE_SCORES
    ]


def shape_score_section(groups: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """The "Shape scores" table: per group, the shape scores averaged over its finished
    trials, per stage."""
    lines = [
        "## Shape scores",
        "",
        "Symmetric Chamfer distance between the completed model and the true surface (mm, "
        "lower is better), F-score at 2 and 5 mm (share of the model within the distance of "
        "the true surface and of the true surface within it of the model, combined; 1 is "
        "perfect) and the volumetric IoU of the model's convex hull with the true solid. "
        "The true surface leaves out the face the object stands on. Averaged over a group's "
        "finished trials.",
        "",
        "| group | trials | " + " | ".join(SHAPE_HEADER) + " |",
        "|---|---|" + "---|" * len(SHAPE_HEADER),
    ]
    for label, group in groups.items():
        cells = shape_cells(finished_rows(group))
        lines.append(f"| {label} | {count_rows(group).text()} | " + " | ".join(cells) + " |")
    return lines


def bias_section(groups: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """The "Bias against the truth" table: per group, Stage 2's bias error across and along
    the plane and in yaw beside the std its covariance claims (medians over the finished
    trials), and the share of trials whose bias lies outside the covariance's 99 % region
    (:func:`pipeline.metrics.evaluation.bias_errors`), after a blank line; empty when no row has
    the scores (a sensor that does not know its calibration error)."""
    scored = {
        label: [row for row in finished_rows(group) if "stage2_bias_nees" in row]
        for label, group in groups.items()
    }
    if not any(scored.values()):
        return []
    lines = [
        "",
        "## Bias against the truth",
        "",
        "How far Stage 2's bias is from the true motion of the camera's cloud onto the object "
        "(the camera's calibration error and the object's motion in the grasp): across the "
        "plane (the direction opposed pads press), along it and in yaw, as |error| / the std "
        "the covariance claims, medians over a group's trials. Outside 99 %: the share of "
        f"trials whose bias NEES exceeds {BIAS_NEES_BOUND:.1f}, 1 % for a covariance that "
        "tells the truth (Stage 1 / Stage 2).",
        "",
        "| group | trials | across (mm) | along (mm) | yaw (deg) | outside 99 % |",
        "|---|---|---|---|---|---|",
    ]
    for label, rows in scored.items():
        if not rows:
            continue
        cells = []
        for name, unit in (("across", "mm"), ("along", "mm"), ("yaw", "deg")):
            error = np.median([abs(row[f"stage2_bias_{name}_error_{unit}"]) for row in rows])
            std = np.median([row[f"stage2_bias_{name}_std_{unit}"] for row in rows])
            cells.append(f"{fmt(error)} / {fmt(std)}")
        outside = [
            np.mean([row[f"stage{k}_bias_nees"] > BIAS_NEES_BOUND for row in rows]) for k in (1, 2)
        ]
        shares = " / ".join(f"{100 * share:.0f} %" for share in outside)
        lines.append(f"| {label} | {len(rows)} | " + " | ".join(cells) + f" | {shares} |")
    return lines


def met(condition: bool) -> str:
    return "met" if condition else "MISSED"
