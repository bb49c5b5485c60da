"""Reports of the synthetic cylinder studies (paper Figs. 8-10): success over the theta x r
grid per tactile angle, stage errors, the estimator's self-diagnosis and failures."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.experiments.common import failures_section, fmt
from pipeline.experiments.sweep import write_csv
from pipeline.reports.figures import GridPanel, error_grid_figure

#: A trial succeeds when the final diameter error is below this (the paper's 4 mm).
SUCCESS_MM = 4.0


#: The region where the paper claims success at the best tactile angle.
CLAIM_THETA_MAX_DEG = 45.0


CLAIM_R_MAX_MM = 30.0


def ok_rows(rows: Iterable[Mapping[str, Any]]) -> tuple[list[Mapping[str, Any]], list[str]]:
    """Rows that ran, and one ``key: error`` line per row that raised."""
    good, failed = [], []
    for row in rows:
        if "error" in row:
            failed.append(f"{row.get('key', '?')}: {row['error']}")
        else:
            good.append(row)
    return good, failed


def final_error(row: Mapping[str, Any]) -> float:
    """The last stage's diameter error (mm); NaN when undefined (counted as a failure)."""
    for stage in (2, 1, 0):
        name = f"stage{stage}_diameter_error_mm"
        if name in row:
            value = row[name]
            return math.nan if value is None else float(value)
    return math.nan


def stage_error(row: Mapping[str, Any], stage: int) -> float:
    value = row.get(f"stage{stage}_diameter_error_mm")
    return math.nan if value is None else float(value)


def error_grid(
    rows: Sequence[Mapping[str, Any]],
    thetas: Sequence[float],
    rs: Sequence[float],
    stage: int | None = None,
) -> np.ndarray:
    """``(len(thetas), len(rs))`` mean diameter error (mm) per grid cell, of ``stage`` or of
    the last stage when None (NaN when missing, or when any run of the cell has no defined
    error)."""
    index_theta = {t: i for i, t in enumerate(thetas)}
    index_r = {r: j for j, r in enumerate(rs)}
    sums = np.zeros((len(thetas), len(rs)))
    counts = np.zeros((len(thetas), len(rs)))
    for row in rows:
        i, j = index_theta[row["params"]["theta_deg"]], index_r[row["params"]["r_mm"]]
        sums[i, j] += final_error(row) if stage is None else stage_error(row, stage)
        counts[i, j] += 1
    with np.errstate(invalid="ignore"):
        return sums / counts


def success_summary(
    grid_mm: np.ndarray, thetas: Sequence[float], rs: Sequence[float]
) -> dict[str, Any]:
    """How much of a theta x r error grid is below :data:`SUCCESS_MM`.

    Returns the number of cells and successes in the paper's claim region (theta <= 45 deg,
    |r| <= 30 mm) and over the whole grid, the largest theta up to which every cell with
    |r| <= 30 mm succeeds, and the largest R such that every cell with theta <= 45 deg and
    |r| <= R succeeds (None when even the smallest fails).
    """
    thetas_a, rs_a = np.asarray(thetas), np.asarray(rs)
    good = np.nan_to_num(grid_mm, nan=np.inf) < SUCCESS_MM
    in_claim = (thetas_a[:, None] <= CLAIM_THETA_MAX_DEG) & (
        np.abs(rs_a)[None, :] <= CLAIM_R_MAX_MM
    )
    theta_reach = None
    for i, theta in enumerate(thetas_a):
        if not np.all(good[i, np.abs(rs_a) <= CLAIM_R_MAX_MM]):
            break
        theta_reach = float(theta)
    r_reach = None
    for radius in np.unique(np.abs(rs_a)):
        cells = (thetas_a[:, None] <= CLAIM_THETA_MAX_DEG) & (np.abs(rs_a)[None, :] <= radius)
        if not np.all(good[cells]):
            break
        r_reach = float(radius)
    return {
        "claim_cells": int(in_claim.sum()),
        "claim_successes": int((good & in_claim).sum()),
        "grid_cells": int(good.size),
        "grid_successes": int(good.sum()),
        "theta_reach_deg": theta_reach,
        "r_reach_mm": r_reach,
    }


#: Final statuses that report a failure (the estimate is not to be trusted).
FLAGGED_STATUSES = ("no_correspondence", "diverged", "inconsistent")


def flagged(row: Mapping[str, Any]) -> bool:
    """The last stage's status reports a failure (:data:`FLAGGED_STATUSES`)."""
    stage = 2 if "stage2_status" in row else 1
    return row.get(f"stage{stage}_status") in FLAGGED_STATUSES


def failure_shares(rows: Sequence[Mapping[str, Any]]) -> tuple[float, float]:
    """The share of ``rows`` that fail (final diameter error not below :data:`SUCCESS_MM`,
    or none) and the share that fail silently (failing, yet their last stage's status is
    not :func:`flagged`); NaN for no rows."""
    if not rows:
        return math.nan, math.nan
    failing = [row for row in rows if not final_error(row) < SUCCESS_MM]
    silent = sum(not flagged(row) for row in failing)
    return len(failing) / len(rows), silent / len(rows)


def percent(share: float) -> str:
    """A share as a percentage for a Markdown table; '-' for none (NaN)."""
    return "-" if math.isnan(share) else fmt(100.0 * share) + " %"


def diagnosis_section(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """Markdown lines on the self-diagnosis: how often a correct result (final diameter
    error < :data:`SUCCESS_MM`) was flagged (a false alarm) and how often a wrong one was
    not (a miss), by the final stage's status."""
    last = [row for row in rows if "stage2_status" in row or "stage1_status" in row]
    if not last:
        return []
    correct = [row for row in last if final_error(row) < SUCCESS_MM]
    wrong = [row for row in last if not final_error(row) < SUCCESS_MM]
    alarms = sum(flagged(row) for row in correct)
    misses = sum(not flagged(row) for row in wrong)
    rate = f" ({100.0 * alarms / len(correct):.1f} %)" if correct else ""
    return [
        "",
        "Self-diagnosis (final status inconsistent, diverged or no_correspondence = flagged): "
        f"{alarms} of {len(correct)} correct results flagged (false alarms{rate}); "
        f"{misses} of {len(wrong)} wrong results not flagged.",
    ]


def _status_counts(rows: Sequence[Mapping[str, Any]]) -> str:
    counts: dict[str, int] = {}
    for row in rows:
        status = str(row.get("stage2_status", row.get("stage1_status", "-")))
        counts[status] = counts.get(status, 0) + 1
    return ", ".join(f"{name} {count}" for name, count in sorted(counts.items()))


def report_grid(
    rows: Sequence[Mapping[str, Any]],
    out_dir: Path,
    *,
    name: str,
    title: str,
    claims: Sequence[str],
) -> list[Path]:
    """CSV, error-map PNG (one panel per tactile angle) and ``report.md`` of a theta x r study.

    The Markdown puts the paper's claims beside, per tactile angle, the successes (final
    diameter error < 4 mm) inside the claim region and over the grid, the median errors of
    each stage in the claim region, the reach of the success region, and the claim-region
    cells that fail.
    """
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    good, failed = ok_rows(rows)
    phis = sorted({row["params"]["tactile_angle_deg"] for row in good}, key=lambda p: (abs(p), p))
    thetas = sorted({row["params"]["theta_deg"] for row in good})
    rs = sorted({row["params"]["r_mm"] for row in good})
    panels, lines = [], []
    lines += [f"# {title}", "", "Paper:", ""]
    lines += [f"- {claim}" for claim in claims]
    lines += [
        "",
        f"Ours: success = final (Stage 2) diameter error < {SUCCESS_MM:g} mm. Claim region: "
        f"theta <= {CLAIM_THETA_MAX_DEG:g} deg and |r| <= {CLAIM_R_MAX_MM:g} mm. Grid: theta "
        f"{', '.join(f'{t:g}' for t in thetas)} deg; r {', '.join(f'{r:g}' for r in rs)} mm.",
        "",
        "| tactile angle | runs | claim region < 4 mm | median err. in claim region "
        "S0 / S1 / S2 (mm) | whole grid < 4 mm | theta reach (|r|<=30) | r reach (theta<=45) "
        "| final status |",
        "|---|---|---|---|---|---|---|---|",
    ]
    failing_lines = []
    for phi in phis:
        subset = [row for row in good if row["params"]["tactile_angle_deg"] == phi]
        line, panel, failing = _grid_angle(phi, subset, thetas, rs)
        lines.append(line)
        panels.append(panel)
        failing_lines += failing
    if failing_lines:
        lines += ["", "Claim-region cells that fail (theta, r): final error in mm:", ""]
        lines += failing_lines
    figure = error_grid_figure(
        panels,
        out_dir / f"{name}.png",
        xlabel="r (mm)",
        ylabel="theta (deg)",
        colour_label=f"final diameter error (mm); outlined: < {SUCCESS_MM:g} mm",
        vmax=20.0,
        threshold=SUCCESS_MM,
        title=title,
    )
    lines += diagnosis_section(good)
    lines += ["", f"![{name}]({figure.name})"]
    lines += failures_section(failed)
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [csv_path, figure, report_path]


def _grid_angle(
    phi: float, subset: Sequence[Mapping[str, Any]], thetas: list[float], rs: list[float]
) -> tuple[str, GridPanel, list[str]]:
    """One tactile angle of a theta x r grid: its table row, its error-map panel, and the
    line listing its claim-region cells that fail (none when all succeed)."""
    final = error_grid(subset, thetas, rs)
    panel = GridPanel(f"tactile angle {phi:+g} deg", np.array(rs), np.array(thetas), final)
    summary = success_summary(final, thetas, rs)
    line = (
        f"| {phi:+g} | {len(subset)} | {summary['claim_successes']}/{summary['claim_cells']} "
        f"| {' / '.join(claim_medians(subset))} "
        f"| {summary['grid_successes']}/{summary['grid_cells']} "
        f"| {fmt(summary['theta_reach_deg'], 2)} | {fmt(summary['r_reach_mm'], 0)} "
        f"| {_status_counts(subset)} |"
    )
    bad = [
        (theta, r, final[i, j])
        for i, theta in enumerate(thetas)
        for j, r in enumerate(rs)
        if theta <= CLAIM_THETA_MAX_DEG
        and abs(r) <= CLAIM_R_MAX_MM
        and not final[i, j] < SUCCESS_MM
    ]
    if not bad:
        return line, panel, []
    cells = ", ".join(f"({t:g}°, {r:+g} mm): {fmt(e)}" for t, r, e in bad[:24])
    more = f" ... {len(bad) - 24} more" if len(bad) > 24 else ""
    return line, panel, [f"- tactile angle {phi:+g}: {cells}{more}"]


def claim_medians(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The median diameter error of Stages 0, 1 and 2 over the rows in the paper's claim
    region, formatted for a table ('-' where none is defined)."""
    in_claim = [row for row in rows if in_claim_region(row)]
    return [
        fmt(float(np.nanmedian([stage_error(row, k) for row in in_claim])))
        if in_claim and any(not math.isnan(stage_error(row, k)) for row in in_claim)
        else "-"
        for k in (0, 1, 2)
    ]


def nearest_angle(angle_deg: float, angles_deg: Sequence[float]) -> float:
    """The angle of ``angles_deg`` nearest to ``angle_deg`` around the circle."""
    gaps = [abs((angle_deg - a + 180.0) % 360.0 - 180.0) for a in angles_deg]
    return angles_deg[int(np.argmin(gaps))]


def in_claim_region(row: Mapping[str, Any]) -> bool:
    """The trial's initial plane error lies in the paper's claim region."""
    params = row["params"]
    return params["theta_deg"] <= CLAIM_THETA_MAX_DEG and abs(params["r_mm"]) <= CLAIM_R_MAX_MM


def failing_share_map(
    rows: Sequence[Mapping[str, Any]], theta_edges: np.ndarray, r_edges: np.ndarray
) -> np.ndarray:
    """``(len(theta_edges) - 1, len(r_edges) - 1)`` failing share (%) of the trials in each
    theta x r cell (NaN for an empty cell)."""
    shape = (len(theta_edges) - 1, len(r_edges) - 1)
    failing, counts = np.zeros(shape), np.zeros(shape)
    for row in rows:
        i = np.searchsorted(theta_edges, row["params"]["theta_deg"], side="right") - 1
        j = np.searchsorted(r_edges, row["params"]["r_mm"], side="right") - 1
        i, j = min(max(i, 0), shape[0] - 1), min(max(j, 0), shape[1] - 1)
        counts[i, j] += 1
        failing[i, j] += not final_error(row) < SUCCESS_MM
    with np.errstate(invalid="ignore"):
        return 100.0 * failing / counts


#: A map cell of failing shares is outlined when fewer than this share (%) of its trials fail.
FAILING_OUTLINE_PERCENT = 10.0


def failing_share_figure(
    panels: Sequence[GridPanel], out_path: Path, *, xlabel: str, ylabel: str, title: str
) -> Path:
    """Maps of failing shares (%), cells under :data:`FAILING_OUTLINE_PERCENT` outlined."""
    return error_grid_figure(
        panels,
        out_path,
        xlabel=xlabel,
        ylabel=ylabel,
        colour_label=f"failing trials (%); outlined: < {FAILING_OUTLINE_PERCENT:g} %",
        vmax=100.0,
        threshold=FAILING_OUTLINE_PERCENT,
        title=title,
    )


def report_random(
    rows: Sequence[Mapping[str, Any]],
    out_dir: Path,
    *,
    name: str,
    title: str,
    claims: Sequence[str],
    tactile_angles_deg: Sequence[float],
) -> list[Path]:
    """CSV, failing-share map PNG and ``report.md`` of a randomised theta x r study.

    Every trial counts for the grid's tactile angle nearest to its own. Per such angle the
    report gives the share of trials that fail (final diameter error >= 4 mm, or none) and
    that fail silently (not flagged), in the paper's claim region and over everything, and
    the stages' median errors in the claim region; the map shows the failing share over
    theta x r cells (11.25 deg x 10 mm), one panel per angle.
    """
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    good, failed = ok_rows(rows)
    angles = sorted(tactile_angles_deg, key=lambda p: (abs(p), p))
    groups = {
        angle: [
            row
            for row in good
            if nearest_angle(row["params"]["tactile_angle_deg"], tactile_angles_deg) == angle
        ]
        for angle in angles
    }
    lines = [f"# {title}", "", "Paper:", ""]
    lines += [f"- {claim}" for claim in claims]
    lines += [
        "",
        f"Ours, randomised: theta, r and the tactile angle drawn uniformly per trial; every "
        f"trial counts for the nearest of the paper's tactile angles. Fail = final (Stage 2) "
        f"diameter error >= {SUCCESS_MM:g} mm or none; silent = failing while the final "
        f"status claims success. Claim region: theta <= {CLAIM_THETA_MAX_DEG:g} deg and "
        f"|r| <= {CLAIM_R_MAX_MM:g} mm.",
        "",
        "| tactile angle | runs | claim region runs | claim region fail / silent "
        "| median err. in claim region S0 / S1 / S2 (mm) | all fail / silent |",
        "|---|---|---|---|---|---|",
    ]
    theta_edges = np.arange(0.0, 90.01, 11.25)
    r_edges = np.arange(-50.0, 50.01, 10.0)
    panels = []
    for angle, subset in groups.items():
        if not subset:
            continue
        claim = [row for row in subset if in_claim_region(row)]
        claim_fail, claim_silent = failure_shares(claim)
        all_fail, all_silent = failure_shares(subset)
        lines.append(
            f"| {angle:+g} | {len(subset)} | {len(claim)} | {percent(claim_fail)} / "
            f"{percent(claim_silent)} | {' / '.join(claim_medians(subset))} | "
            f"{percent(all_fail)} / {percent(all_silent)} |"
        )
        panels.append(
            GridPanel(
                f"tactile angle near {angle:+g} deg",
                0.5 * (r_edges[1:] + r_edges[:-1]),
                0.5 * (theta_edges[1:] + theta_edges[:-1]),
                failing_share_map(subset, theta_edges, r_edges),
            )
        )
    lines += diagnosis_section(good)
    paths = [csv_path]
    if panels:
        figure = failing_share_figure(
            panels, out_dir / f"{name}.png", xlabel="r (mm)", ylabel="theta (deg)", title=title
        )
        paths.append(figure)
        lines += ["", f"![{name}]({figure.name})"]
    lines += failures_section(failed)
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [*paths, report_path]
