"""The headline rows a benchmark adds to the summary table of ``bench/run_all.py``.

A benchmark calls :func:`record` for each number that has a target. Run by ``run_all.py``
(which names a file in ``SYMFUSE_BENCH_SUMMARY``), the rows are appended there as JSON
lines; run on its own, :func:`record` does nothing and the benchmark prints its own table.
"""

from __future__ import annotations

import json
import os

#: Environment variable naming the JSON-lines file the rows go to.
SUMMARY_FILE = "SYMFUSE_BENCH_SUMMARY"


def record(
    measure: str, value: float, unit: str, target: float | None = None, *, at_most: bool = True
) -> None:
    """Add one row: ``measure`` came out at ``value`` (in ``unit``); the target, if any, is
    ``value <= target`` (``at_most``) or ``value >= target``."""
    path = os.environ.get(SUMMARY_FILE)
    if not path:
        return
    value = float(value)  # numpy scalars do not serialise
    met = None if target is None else bool(value <= target if at_most else value >= target)
    row = {"measure": measure, "value": value, "unit": unit, "target": target}
    row.update(at_most=at_most, met=met)
    with open(path, "a", encoding="utf-8") as summary:
        summary.write(json.dumps(row) + "\n")
