"""The benchmarks in ``bench/`` stay runnable as the code under them changes.

Each benchmark is a script run by ``bench/run_all.py``; nothing else calls them, so an API
change would only show when somebody runs ``tox -e bench``. These tests import every script
and run the parts that call into the pipeline at a small size, each in a fresh interpreter
(the scripts set thread variables and import paths of their own).
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"
SCRIPTS = sorted(p.stem for p in BENCH.glob("*.py"))


def run_in_bench(code: str) -> str:
    """Run ``code`` in a new interpreter with ``bench/`` importable; its stdout."""
    prelude = f"import sys; sys.path.insert(0, {str(BENCH)!r})\n"
    done = subprocess.run(
        [sys.executable, "-c", prelude + textwrap.dedent(code)],
        capture_output=True,
        text=True,
        cwd=BENCH,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_every_benchmark_script_imports():
    imports = "".join(f"import {name}\n" for name in SCRIPTS)
    run_in_bench(imports)


@pytest.mark.slow
def test_the_estimator_benchmark_times_both_covariance_models():
    out = run_in_bench(
        """
        import estimator
        for start in estimator.STARTS.values():
            row = estimator.estimate_row(2000, start, 1)
            print(row["status"], row["per_iteration_s"] > 0)
        seconds, iterations = estimator.filter_seconds(False, 1)
        print(seconds > 0, len(iterations))
        """
    )
    assert out.split() == ["converged/converged", "True"] * 5 + ["True", "2"]


@pytest.mark.slow
def test_the_sweep_overhead_benchmark_runs_a_real_sweep(tmp_path):
    out = run_in_bench(
        f"""
        from pathlib import Path
        import sweep_overhead
        result = sweep_overhead.experiment_sweep("fig10", 4, Path({str(tmp_path)!r}), True)
        print(result["tasks"], result["trial_s"] > 0, result["start_up_s"] >= 0)
        """
    )
    assert out.split() == ["4", "True", "True"]


def test_overhead_shares_of_two_workers_by_hand():
    sys.path.insert(0, str(BENCH))
    try:
        from sweep_overhead import overhead_shares
    finally:
        sys.path.remove(str(BENCH))

    def row(pid, start, end, trial):
        return {"bench_pid": pid, "bench_start": start, "bench_end": end, "timings": {"t": trial}}

    # Worker 1: first task waits 1 s and runs 3 s (its others take 1 s): start-up 1 + 2 s.
    # Each later task: 0.1 s gap before it and 0.1 s of run_one outside the trial's 0.9 s.
    rows = [
        row(1, 1.0, 4.0, 2.9),
        row(1, 4.1, 5.1, 0.9),
        row(1, 5.2, 6.2, 0.9),
        row(2, 2.0, 3.0, 0.9),
        row(2, 3.1, 4.1, 0.9),
        row(2, 4.2, 5.2, 0.9),
    ]
    shares = overhead_shares(rows, started=0.0, ended=7.0)
    assert shares["trial_s"] == pytest.approx(0.9)
    assert shares["steady"] == pytest.approx(0.2 / 0.9)
    # Worker 1: 1 s wait + (3 - 1) s first-task excess; worker 2: 2 s wait, no excess.
    assert shares["start_up_s"] == pytest.approx((3.0 + 2.0) / 2)
    assert shares["tail_s"] == pytest.approx(0.8)
    assert shares["whole"] == pytest.approx((2 * 7.0 / 6 - 0.9) / 0.9)
    assert shares["per_minute"] == pytest.approx(60.0 * 6 / 7.0)


@pytest.mark.slow
def test_the_scan_benchmark_runs_a_trial_on_a_folder_of_scans(tmp_path):
    # A catalogue mesh stands in for a scan: the script needs only DIR/<name>/textured.obj.
    from pipeline.catalogue.objects import load_object

    (tmp_path / "jar").mkdir()
    load_object("jam").mesh.export(tmp_path / "jar" / "textured.obj")
    done = subprocess.run(
        [sys.executable, str(BENCH / "ycb_trials.py"), "--root", str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=BENCH,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "jar/yaw00" in done.stdout
    assert "1/1 trials fused their grasp (pads on opposing sides)" in done.stdout


def test_the_scan_target_by_hand():
    sys.path.insert(0, str(BENCH))
    try:
        from ycb_trials import meets
    finally:
        sys.path.remove(str(BENCH))
    assert meets(1.0, 1.2)  # 0.2 mm worse: within the tolerance
    assert not meets(1.0, 1.3)
    assert meets(6.0, 4.0)  # better, under 5 mm
    assert not meets(6.0, 5.5)  # better than Stage 0 but above 5 mm
    assert not meets(None, 1.0) and not meets(1.0, float("nan"))


@pytest.mark.slow
def test_the_planner_check_plans_a_catalogue_object_as_a_trial_would(tmp_path):
    out = run_in_bench(
        f"""
        import json
        from pathlib import Path
        import planner_check
        inputs, out = Path({str(tmp_path)!r}) / "inputs.npz", Path({str(tmp_path)!r}) / "out.json"
        print(planner_check.make_inputs(["salt_cylinder"], [0.0], inputs))
        planner_check.plan_cases(inputs, out)
        found = json.loads(out.read_text())
        table = found["cases"]["salt_cylinder@0"]["candidates"]
        print(len(table) > 0, found["seconds"] > 0, planner_check.differences(found, found))
        """
    )
    assert out.split("\n")[:2] == ["['salt_cylinder@0']", "True True []"]


def test_planner_check_differences_by_hand():
    out = run_in_bench(
        """
        import math
        from planner_check import differences
        print(differences({"a": [1.0, math.nan, "x"]}, {"a": [1.5, math.nan, "x"]}))
        print(differences({"a": [1.0]}, {"a": [1.0, 2.0]}))
        print(differences({"a": True}, {"b": True}))
        """
    )
    assert out.split("\n")[:3] == [
        "[('/a', 0.5)]",
        "[('/a: length 1 vs 2', nan)]",
        "[(': keys', nan)]",
    ]


@pytest.mark.slow
def test_the_evaluation_benchmark_records_a_trial_and_scores_it_again_alike():
    out = run_in_bench(
        """
        import evaluation
        inputs = evaluation.recorded_inputs("default")
        seconds, results, _ = evaluation.measure(inputs, 1, False)
        again = evaluation.evaluate(inputs)
        found = evaluation.differences(*map(evaluation.plain, (results, again)))
        print(len(inputs["stages"]), seconds[0] > 0, found)
        results[0][0][0]["iou"] += 1e-12
        found = evaluation.differences(*map(evaluation.plain, (results, again)))
        print([where for where, _ in found])
        """
    )
    assert out.split("\n")[:2] == ["3 True []", "['/iou']"]
