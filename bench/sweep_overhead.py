"""Sweep overhead: the engine's cost per task, real sweeps' trials per minute on two
workers with the per-trial overhead, and catalogue generation time.

First trivial tasks (a few microseconds of work each) through every executor, so the time
per task is what the engine itself costs: JSON encoding, the fsynced append, process or
cluster dispatch (target: under 5 % of a 1 s trial). Then the first tasks of ``table3``
(simulated PyBullet trials) and ``fig10`` (synthetic estimator trials) on two local worker
processes: trials per minute and where the time went (:func:`overhead_shares`): the
per-trial overhead a sweep adds to every trial (target: at most 10 % of the trial time), and
the costs paid once per sweep (each worker's start, the tail), also as a share of the trial
time at the sweep's size. ``table3`` runs twice: with a new PyBullet client per trial
(``SYMFUSE_PYBULLET_REUSE=0``) and with each worker's client reused. Usage:
``python bench/sweep_overhead.py [--tasks N] [--table3 N] [--fig10 N]``.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import os
import statistics
import tempfile
import time
from pathlib import Path

from summary import record

from pipeline.experiments import EXPERIMENTS, ExperimentOptions, SweepTask
from pipeline.experiments.sweep import run_sweep

#: ``pipeline.sim.world.REUSE_VARIABLE``, not imported: the workers import this module, and
#: the simulation's imports would count as their start-up.
REUSE_VARIABLE = "SYMFUSE_PYBULLET_REUSE"

OVERHEAD_TARGET_S = 0.05  # 5 % of a 1 s trial
CATALOGUE_TARGET_S = 2.0  # generating all objects once, cold
#: Largest per-trial overhead of a real sweep, as a share of the trial time.
TRIAL_OVERHEAD_TARGET = 0.10
SWEEP_WORKERS = 2


def time_sweep(tasks: list[SweepTask], folder: Path, label: str, **options) -> float:
    start = time.perf_counter()
    # ``dict`` is the trivial trial: params in, a copy out; picklable in any worker.
    run_sweep(tasks, dict, folder / f"{label}.jsonl", progress=False, **options)
    return (time.perf_counter() - start) / len(tasks)


def timed_run_one(experiment: str, params: dict) -> dict:
    """The experiment's ``run_one`` with the worker's pid and the task's start and end on the
    machine's monotonic clock (``bench_*``), comparable across processes."""
    started = time.monotonic()
    row = EXPERIMENTS[experiment].run_one(params)
    return {**row, "bench_pid": os.getpid(), "bench_start": started, "bench_end": time.monotonic()}


def trial_seconds(row: dict) -> float:
    """The trial's own time in a row of :func:`timed_run_one` (see :func:`overhead_shares`)."""
    if "timings" in row:
        return sum(row["timings"].values())
    return row["bench_end"] - row["bench_start"]


def overhead_shares(rows: list[dict], started: float, ended: float) -> dict:
    """Where a sweep's time went, from the rows of :func:`timed_run_one`.

    The trial is what ``run_trial`` timed (the sum of the row's phase ``timings``), or for
    experiments without a simulated trial (``fig10``) the whole ``run_one``; its mean leaves
    out each worker's first task, whose first calls are the worker's start. The
    steady-state per-trial overhead is everything else a worker spent on a task after its
    first (registry, config, PyBullet client, output folder, the row) plus its idle gap before
    the task: the cost a sweep adds to each trial however long it runs. The fixed costs are
    paid once per sweep: each worker's start (spawn, imports and first-call costs, measured as
    the wait for its first task plus that task's excess over the worker's median) and the tail
    (the last worker's end until the sweep returned, with workers idle while the others
    finish).
    """
    by_worker: dict[int, list[dict]] = {}
    for row in rows:
        by_worker.setdefault(row["bench_pid"], []).append(row)
    trial, steady, start_up = [], [], []
    for worker_rows in by_worker.values():
        worker_rows.sort(key=lambda row: row["bench_start"])
        spans = [row["bench_end"] - row["bench_start"] for row in worker_rows]
        typical = statistics.median(spans[1:]) if len(spans) > 1 else spans[0]
        start_up.append(worker_rows[0]["bench_start"] - started + spans[0] - typical)
        for before, row in itertools.pairwise(worker_rows):
            trial.append(trial_seconds(row))
            gap = row["bench_start"] - before["bench_end"]
            steady.append(gap + row["bench_end"] - row["bench_start"] - trial_seconds(row))
    trial_s = statistics.mean(trial) if trial else statistics.mean(map(trial_seconds, rows))
    wall = ended - started
    return {
        "tasks": len(rows),
        "per_minute": 60.0 * len(rows) / wall,
        "trial_s": trial_s,
        "steady": statistics.mean(steady) / trial_s,
        "start_up_s": statistics.mean(start_up),
        "tail_s": ended - max(row["bench_end"] for row in rows),
        "whole": (SWEEP_WORKERS * wall / len(rows) - trial_s) / trial_s,
    }


def experiment_sweep(experiment: str, count: int, folder: Path, reuse: bool) -> dict:
    """Run the first ``count`` tasks of ``experiment`` (repeated grids as needed) on
    :data:`SWEEP_WORKERS` workers; trials per minute and :func:`overhead_shares`."""
    definition = EXPERIMENTS[experiment]
    tasks = definition.tasks(ExperimentOptions())
    if len(tasks) < count:
        tasks = definition.tasks(ExperimentOptions(repeats=-(-count // len(tasks))))
    tasks = tasks[:count]
    os.environ[REUSE_VARIABLE] = "1" if reuse else "0"  # the spawned workers inherit it
    started = time.monotonic()
    rows = run_sweep(
        tasks,
        functools.partial(timed_run_one, experiment),
        folder / f"{experiment}-{reuse}.jsonl",
        workers=SWEEP_WORKERS,
        progress=False,
    )
    ended = time.monotonic()
    os.environ.pop(REUSE_VARIABLE)
    failed = [row for row in rows if "error" in row]
    if failed:
        raise RuntimeError(f"{experiment}: {failed[0]['key']}: {failed[0]['error']}")
    return overhead_shares(rows, started, ended)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", type=int, default=200, help="tasks per executor")
    parser.add_argument("--table3", type=int, default=40, help="table3 trials per sweep")
    parser.add_argument("--fig10", type=int, default=120, help="fig10 trials")
    args = parser.parse_args()
    tasks = [SweepTask(f"t{i:05d}", {"x": i, "seed": i}) for i in range(args.tasks)]

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rows.append(("in-process (workers=1)", time_sweep(tasks, folder, "w1", workers=1)))
        rows.append(("process pool (workers=2)", time_sweep(tasks, folder, "w2", workers=2)))
        try:
            from dask.distributed import LocalCluster
        except ImportError:
            print("dask.distributed not installed: skipping the dask executor")
        else:
            with LocalCluster(
                n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster:
                per_task = time_sweep(
                    tasks, folder, "dask", executor="dask", scheduler=cluster.scheduler_address
                )
            rows.append(("dask LocalCluster (2 workers)", per_task))
        resumed = time_sweep(tasks, folder, "w1", workers=1)
        rows.append(("re-run, all tasks finished", resumed))

    from pipeline.catalogue import objects as catalogue

    start = time.perf_counter()
    for info in catalogue.list_objects():
        catalogue.load_object(info.name)
    generation_s = time.perf_counter() - start

    print(f"{'measure':56s} {'measured':>12s} {'target':>10s}")
    for label, per_task_s in rows:
        print(
            f"{'engine time per task, ' + label:56s} {per_task_s * 1e3:9.2f} ms "
            f"{'< ' + format(OVERHEAD_TARGET_S * 1e3, '.0f') + ' ms':>10s}"
        )
        record(f"sweep engine time per task, {label}", per_task_s, "s", OVERHEAD_TARGET_S)
    print(
        f"{'catalogue: generate all objects (cold)':56s} {generation_s:10.3f} s "
        f"{'< ' + format(CATALOGUE_TARGET_S, '.0f') + ' s':>10s}"
    )
    print(f"({args.tasks} trivial tasks per executor; pool and cluster start-up included)")
    record("catalogue: generate all objects (cold)", generation_s, "s", CATALOGUE_TARGET_S)

    print()
    print(f"real sweeps on {SWEEP_WORKERS} local workers")
    header = (
        f"{'sweep':<38} {'trials':>6} {'per min':>8} {'trial s':>8} {'per-trial':>9} "
        f"{'target':>7} {'start s':>8} {'tail s':>7} {'whole':>7}"
    )
    print(header)
    print("-" * len(header))
    runs = (
        ("table3", args.table3, False, "new PyBullet client per trial"),
        ("table3", args.table3, True, "workers reuse their client"),
        ("fig10", args.fig10, True, "no PyBullet"),
    )
    with tempfile.TemporaryDirectory() as tmp:
        for experiment, count, reuse, how in runs:
            result = experiment_sweep(experiment, count, Path(tmp), reuse)
            label = f"{experiment}, {how}"
            print(
                f"{label:<38} {result['tasks']:>6} {result['per_minute']:>8.1f} "
                f"{result['trial_s']:>8.2f} {result['steady']:>9.1%} "
                f"{TRIAL_OVERHEAD_TARGET:>7.0%} {result['start_up_s']:>8.2f} "
                f"{result['tail_s']:>7.2f} {result['whole']:>7.1%}"
            )
            record(
                f"sweep {label}: {result['per_minute']:.1f} trials/min on {SWEEP_WORKERS} "
                f"workers; per-trial overhead / trial time ({result['trial_s']:.2f} s)",
                100.0 * result["steady"],
                "%",
                100.0 * TRIAL_OVERHEAD_TARGET,
            )
            record(
                f"sweep {label}: once per sweep, each worker's start "
                f"({result['start_up_s']:.2f} s) and the tail ({result['tail_s']:.2f} s): all "
                f"overhead / trial time at {result['tasks']} trials",
                100.0 * result["whole"],
                "%",
            )
    print(
        "per-trial: registry, config, PyBullet client, output folder, the row and the gap "
        "between tasks, as a share of the trial; start s: a worker's spawn, imports and "
        "first-call costs; tail s: idle workers at the end and the pool's shutdown; whole: "
        "everything the sweep added, start and tail included, as a share of the trial time"
    )


if __name__ == "__main__":
    main()
