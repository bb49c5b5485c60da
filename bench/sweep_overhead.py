"""Sweep overhead: the engine's cost per task, real sweeps' trials per minute on two
workers with the per-trial overhead, and catalogue generation time.

First trivial tasks (a few microseconds of work each) through every executor, so the time
per task is what the engine itself costs: JSON encoding, the fsynced append, process or
cluster dispatch (target: under 5 % of a 1 s trial). Then the first tasks of ``table3``
(simulated PyBullet trials) and ``fig10`` (synthetic estimator trials) on two local worker
processes: trials per minute, and the per-trial overhead, ``2 x wall / tasks`` less the mean
time a worker spent inside the experiment's ``run_one``: everything a sweep adds to its
trials (worker start and imports, registry, dispatch, the results file, idle workers at the
end), as a share of that trial time (target: at most 10 %). ``table3`` runs twice: with a new
PyBullet client per trial (``SYMFUSE_PYBULLET_REUSE=0``, as before workers kept theirs) and
with each worker's client reused. Usage:
``python bench/sweep_overhead.py [--tasks N] [--table3 N] [--fig10 N]``.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import tempfile
import time
from pathlib import Path

from summary import record

from pipeline.experiments import EXPERIMENTS, ExperimentOptions, SweepTask
from pipeline.sweep import run_sweep

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
    """The experiment's ``run_one`` with its wall time in the row (``bench_run_one_s``)."""
    run_one = importlib.import_module(EXPERIMENTS[experiment]).run_one
    started = time.perf_counter()
    row = run_one(params)
    return {**row, "bench_run_one_s": time.perf_counter() - started}


def experiment_sweep(experiment: str, count: int, folder: Path, reuse: bool) -> dict:
    """Run the first ``count`` tasks of ``experiment`` (repeated grids as needed) on
    :data:`SWEEP_WORKERS` workers; trials per minute and the per-trial overhead."""
    module = importlib.import_module(EXPERIMENTS[experiment])
    tasks = module.tasks(ExperimentOptions())
    if len(tasks) < count:
        tasks = module.tasks(ExperimentOptions(repeats=-(-count // len(tasks))))
    tasks = tasks[:count]
    os.environ[REUSE_VARIABLE] = "1" if reuse else "0"  # the spawned workers inherit it
    started = time.perf_counter()
    rows = run_sweep(
        tasks,
        functools.partial(timed_run_one, experiment),
        folder / f"{experiment}-{reuse}.jsonl",
        workers=SWEEP_WORKERS,
        progress=False,
    )
    wall = time.perf_counter() - started
    os.environ.pop(REUSE_VARIABLE)
    failed = [row for row in rows if "error" in row]
    if failed:
        raise RuntimeError(f"{experiment}: {failed[0]['key']}: {failed[0]['error']}")
    trial_s = sum(row["bench_run_one_s"] for row in rows) / len(rows)
    overhead_s = SWEEP_WORKERS * wall / len(rows) - trial_s
    return {
        "tasks": len(rows),
        "per_minute": 60.0 * len(rows) / wall,
        "trial_s": trial_s,
        "overhead": overhead_s / trial_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", type=int, default=200, help="tasks per executor")
    parser.add_argument("--table3", type=int, default=16, help="table3 trials per sweep")
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

    from pipeline import catalogue

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
    print(f"real sweeps on {SWEEP_WORKERS} local workers (worker start-up included)")
    header = (
        f"{'sweep':<42} {'trials':>6} {'per min':>8} {'trial s':>8} {'overhead':>9} {'target':>7}"
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
                f"{label:<42} {result['tasks']:>6} {result['per_minute']:>8.1f} "
                f"{result['trial_s']:>8.2f} {result['overhead']:>8.1%} "
                f"{TRIAL_OVERHEAD_TARGET:>6.0%}"
            )
            record(
                f"sweep {label}: {result['per_minute']:.1f} trials/min on {SWEEP_WORKERS} "
                f"workers; per-trial overhead / trial time ({result['trial_s']:.2f} s)",
                100.0 * result["overhead"],
                "%",
                100.0 * TRIAL_OVERHEAD_TARGET,
            )


if __name__ == "__main__":
    main()
