"""The tables the run verbs print: Stages 0, 1, 2 with their self-diagnosis, and the
stage the estimator stands behind."""

from __future__ import annotations

import numpy as np

from pipeline.reports.tables import format_table

#: Columns of the self-diagnosis in the stage tables.
CONSISTENCY_HEADER = ["taxel rms mm", "NIS / bound", "free space / limit", "consistent"]


def consistency_cells(stage) -> list[str]:
    """A stage's self-diagnosis as table cells ('-' where a check did not run)."""
    c = stage.consistency
    if c is None:
        return ["-"] * len(CONSISTENCY_HEADER)
    free = (
        "-"
        if c.free_space_violations is None
        else f"{c.free_space_violations} / {c.free_space_limit}"
    )
    rms = "-" if not np.isfinite(c.taxel_rms_m) else f"{c.taxel_rms_m * 1e3:.1f}"
    nis = "-" if not np.isfinite(c.nis) else f"{c.nis:.2f} / {c.nis_threshold:.2f}"
    return [rms, nis, free, "yes" if c.consistent else "NO"]


def selection_line(result) -> str:
    """Which stage the estimator stands behind, and why."""
    return f"selected: Stage {result.selected.stage} ({result.selection_reason})"


def one_sided_line(numbers: list[int]) -> str:
    """A note on the grasps that touched one side only or nothing (numbers from 1), or
    ``""`` when there are none."""
    if not numbers:
        return ""
    which = ", ".join(str(k) for k in numbers)
    several = len(numbers) > 1
    return (
        f"note: grasp{'s' * several} {which} touched one side only or nothing: "
        f"{'their' if several else 'its'} taxels cannot tell how far the pads pushed the "
        "object from how wide it is, and a trial does not fuse such a grasp "
        "(docs/method.md §11)"
    )


#: The columns of :func:`stage_summary` only ``--wide`` shows (the self-diagnosis's numbers;
#: all are in ``result.json``).
WIDE_STAGE_COLUMNS = tuple(CONSISTENCY_HEADER[:-1])


def stage_summary(result, wide: bool = False) -> str:
    """A small table of Stage 0/1/2: status, plane, bias, iterations, time, self-diagnosis
    (less :data:`WIDE_STAGE_COLUMNS` unless ``wide``)."""
    rows = []
    for stage in result.stages:
        rows.append(
            [
                stage.stage,
                stage.status,
                f"{np.degrees(stage.plane.theta_rad):.2f}",
                f"{stage.plane.offset_m * 1e3:.1f}",
                f"{np.degrees(stage.bias.yaw_rad):.2f}",
                " ".join(f"{v * 1e3:.1f}" for v in stage.bias.translation_m),
                stage.iterations,
                f"{stage.seconds * 1e3:.0f}",
                *consistency_cells(stage),
            ]
        )
    header = ["stage", "status", "plane θ°", "offset mm", "yaw°", "bias t (mm)", "iter", "ms"]
    return format_table(header + CONSISTENCY_HEADER, rows, () if wide else WIDE_STAGE_COLUMNS)
