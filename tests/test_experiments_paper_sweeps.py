"""End to end: each real-object experiment's quick grid through the sweep engine and its
report (slow: two or three full simulated trials per experiment)."""

from __future__ import annotations

import re

import pytest

from pipeline.experiments import EXPERIMENTS, ExperimentOptions
from pipeline.experiments.sweep import run_sweep

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("name", ["table1", "table2", "table3", "spray", "kth"])
def test_quick_sweep_runs_and_reports(name, tmp_path):
    module = EXPERIMENTS[name]
    tasks = module.tasks(ExperimentOptions(quick=True))
    rows = run_sweep(tasks, module.run_one, tmp_path / "results.jsonl", workers=1, progress=False)
    assert [row["key"] for row in rows] == [task.key for task in tasks]
    assert not [row["error"] for row in rows if "error" in row]
    finished = [row for row in rows if not row["failed"]]
    assert finished, [row["failed"] for row in rows]
    for row in finished:
        assert {"stage0_deviation_median_mm", "stage2_deviation_median_mm"} <= set(row)
    paths = module.report(rows, tmp_path)
    assert all(path.is_file() and path.stat().st_size > 0 for path in paths)
    report = (tmp_path / "report.md").read_text()
    # Every table gives "finished/total" per group (spray and kth also the whole sweep's).
    tables = [re.findall(r"(\d+)/(\d+) finished", block) for block in report.split("\n\n")]
    tables = [[(int(a), int(b)) for a, b in counts] for counts in tables if counts]
    assert tables
    for counts in tables:
        assert (len(finished), len(rows)) in counts or sum(a for a, _ in counts) == len(finished)
