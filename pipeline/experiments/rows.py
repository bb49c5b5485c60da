"""Selecting, grouping and summarising the result rows of the paper experiments."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Deviation summary fields, in box-plot order, then the mean.
FIVE_NUMBERS = ("min", "q1", "median", "q3", "max")


STAGES = (0, 1, 2)


#: Display names of the initialisers.
INIT_LABELS = {"ps": "PS", "vc": "VC", "pca": "PCA"}


@dataclass(frozen=True)
class RowCounts:
    """How the rows of one group ended: finished, failed (a stage refused), diverged,
    raised (an exception: the sweep's error rows)."""

    total: int
    finished: int
    failed: int
    diverged: int
    raised: int

    def text(self) -> str:
        return (
            f"{self.finished}/{self.total} finished, {self.failed} failed, "
            f"{self.diverged} diverged, {self.raised} raised"
        )


def finished_rows(rows: Iterable[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """Rows of trials that ran to the end (neither raised nor failed)."""
    return [row for row in rows if "error" not in row and not row.get("failed")]


def count_rows(rows: Sequence[Mapping[str, Any]]) -> RowCounts:
    finished = finished_rows(rows)
    return RowCounts(
        total=len(rows),
        finished=len(finished),
        failed=sum(1 for row in rows if "error" not in row and row.get("failed")),
        diverged=sum(1 for row in finished if row.get("diverged")),
        raised=sum(1 for row in rows if "error" in row),
    )


def failure_lines(rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """``key: reason`` for every row that raised or failed."""
    lines = []
    for row in rows:
        if "error" in row:
            lines.append(f"{row.get('key', '?')}: {row['error']}")
        elif row.get("failed"):
            lines.append(f"{row.get('key', '?')}: failed: {row['failed']}")
    return lines


def value(row: Mapping[str, Any], name: str) -> float:
    """A numeric field of a row; NaN when missing or None."""
    field = row.get(name)
    return math.nan if field is None else float(field)


def group_rows(
    rows: Iterable[Mapping[str, Any]], key: Callable[[Mapping[str, Any]], Any]
) -> dict[Any, list[Mapping[str, Any]]]:
    """Rows grouped by ``key(row)``, groups in first-seen order."""
    groups: dict[Any, list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault(key(row), []).append(row)
    return groups


def mean_value(rows: Sequence[Mapping[str, Any]], name: str) -> float:
    """The mean of a numeric field over ``rows``, ignoring missing values; NaN if none."""
    values = np.array([value(row, name) for row in rows])
    return float(np.nanmean(values)) if np.isfinite(values).any() else math.nan


def mean_five_numbers(rows: Sequence[Mapping[str, Any]], stage: int) -> np.ndarray:
    """The deviation box (min, q1, median, q3, max; mm) of ``stage`` averaged over ``rows``:
    the paper's Fig. 23 averages the box-and-whisker data of an object's poses."""
    table = np.array(
        [[value(row, f"stage{stage}_deviation_{name}_mm") for name in FIVE_NUMBERS] for row in rows]
    )
    return np.nanmean(table, axis=0)


def rest_fields(rest: Mapping[str, Any] | None) -> dict[str, Any]:
    """The row fields of the object's rest pose, from ``result.json``'s ``rest`` entry
    (None: upright, as loaded): ``rest_pose`` (``"upright"`` or the stable pose's number),
    ``rest_probability`` and ``rest_keeps_vertical`` (whether it stands on its base or top)."""
    if rest is None:
        return {"rest_pose": "upright", "rest_probability": None, "rest_keeps_vertical": True}
    return {
        "rest_pose": rest["index"],
        "rest_probability": rest["probability"],
        "rest_keeps_vertical": rest["keeps_vertical"],
    }
