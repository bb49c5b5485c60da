"""Engine overhead of ``pipeline.sweep.run_sweep`` per task, and catalogue generation time.

Runs trivial tasks (a few microseconds of work each) through every executor, so the time per
task is what the engine itself costs: JSON encoding, the fsynced append, process or cluster
dispatch. A paper trial takes seconds, so the target is that the engine adds under 5 % of a
1 s trial. Usage: ``python bench/sweep_overhead.py [--tasks N]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from summary import record

from pipeline import catalogue
from pipeline.experiments import SweepTask
from pipeline.sweep import run_sweep

OVERHEAD_TARGET_S = 0.05  # 5 % of a 1 s trial
CATALOGUE_TARGET_S = 2.0  # generating all objects once, cold


def time_sweep(tasks: list[SweepTask], folder: Path, label: str, **options) -> float:
    start = time.perf_counter()
    # ``dict`` is the trivial trial: params in, a copy out; picklable in any worker.
    run_sweep(tasks, dict, folder / f"{label}.jsonl", progress=False, **options)
    return (time.perf_counter() - start) / len(tasks)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", type=int, default=200, help="tasks per executor")
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


if __name__ == "__main__":
    main()
