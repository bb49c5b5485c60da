"""Estimator benchmark: the ``iekf`` estimator at N = 20k / 100k / 1M points, Stages 0-2 in
total, and the dense reference IEKF against the structured one at N = 1,500.

Run: ``python bench/estimator.py``. Single-threaded BLAS (set below, before numpy loads).
Every structured row runs in a fresh process (``--points N``), warmed up on a small problem
first, so its peak memory (``ru_maxrss``) is that of one estimate at that size.

``total s`` is the whole :meth:`IekfEstimator.estimate` call, what a user waits for and what
the result's stage times add up to: Stage 0 (the set-up: the kernel's arrays and the point
index), Stages 1 and 2, and the self-diagnosis of the three stages (taxel check only: the
bench has no depth image); ``cpu s`` is its processor time (less sensitive to a busy
machine) and ``S0 / S1 / S2`` the stages' own wall times (each with its share of the
diagnosis). ``iters`` are Stage 1's and Stage 2's iteration counts, so a faster row
cannot come from stopping early. The dense / structured ratio compares Stages 1-2 (the
filter itself, the only part the covariance model changes) in the same process.

Input: the visible half of a 40 mm radius, 100 mm tall cylinder, sampled uniformly, grasped
by two opposed 6 x 14 taxel pads (the taxels within 0.6 mm of the surface touch), with a
3 mm / 1.7 deg bias and an 8 mm / 4.6 deg plane error; ``iekf`` plugin defaults.
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import itertools  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from summary import record  # noqa: E402

from pipeline.estimation.dense import DenseCovariance  # noqa: E402
from pipeline.estimation.geometry import apply_bias  # noqa: E402
from pipeline.estimation.iekf import fuse  # noqa: E402
from pipeline.estimation.map_params import fusion_problem  # noqa: E402
from pipeline.types import (  # noqa: E402
    Bias,
    Contacts,
    EstimationProblem,
    PointCloud,
    SymmetryInit,
    SymmetryPlane,
)
from plugins.iekf import IekfEstimator  # noqa: E402

RADIUS_M, HEIGHT_M, PITCH_M = 0.04, 0.10, 0.0034
#: Wall-time targets of the whole estimate (Stages 0-2, set-up included), one thread.
TARGETS_S = {20_000: 0.25, 100_000: 0.6, 1_000_000: 5.0}
#: Peak resident memory of the process estimating the largest cloud.
MEMORY_TARGET_GB = 2.0
DENSE_RATIO_TARGET = 100.0
REPEATS = {20_000: 5, 100_000: 5, 1_000_000: 2}
DENSE_N, DENSE_REPEATS = 1_500, 1


def cylinder_problem(n_points: int, seed: int = 0) -> EstimationProblem:
    rng = np.random.default_rng(seed)
    angle = rng.uniform(np.pi / 2, 3 * np.pi / 2, n_points)
    points = np.column_stack(
        [RADIUS_M * np.cos(angle), RADIUS_M * np.sin(angle), rng.uniform(0, HEIGHT_M, n_points)]
    )
    points += rng.normal(0.0, 0.0005, points.shape)
    g_true = np.array([0.03, 0.003, -0.002, 0.001, 0.0, 0.0])
    axis = apply_bias(np.zeros((1, 3)), g_true, points.mean(axis=0))[0]
    col, row = np.meshgrid((np.arange(6) - 2.5) * PITCH_M, (np.arange(14) - 6.5) * PITCH_M)
    touching = (RADIUS_M - np.sqrt(RADIUS_M**2 - col**2) < 0.0006).ravel()
    taxels, normals, pads = [], [], []
    for sign, pad in ((-1.0, "left"), (1.0, "right")):
        grid = np.column_stack(
            [
                np.full(row.size, axis[0] + sign * RADIUS_M),
                axis[1] + col.ravel(),
                row.ravel() + HEIGHT_M / 2,
            ]
        )[touching]
        taxels.append(grid)
        normals.append(np.tile([-sign, 0.0, 0.0], (len(grid), 1)))
        pads.append(np.full(len(grid), pad))
    contacts = Contacts(
        positions=np.concatenate(taxels),
        normals=np.concatenate(normals),
        pads=np.concatenate(pads),
        taxel_indices=np.arange(sum(len(t) for t in taxels)),
    )
    init = SymmetryInit(plane=SymmetryPlane(theta_rad=0.08, offset_m=0.008), bias=Bias())
    return EstimationProblem(cloud=PointCloud(points), init=init, grasps=(contacts,))


def estimate_row(n_points: int, repeats: int) -> dict:
    """Median wall time of ``repeats`` whole estimates of the N-point problem, its stages'
    median times, the last run's iterations and statuses, and this process's peak memory."""
    estimator = IekfEstimator()
    estimator.estimate(cylinder_problem(DENSE_N, seed=1))  # imports and first-call costs
    problem = cylinder_problem(n_points)
    totals, cpu, stages = [], [], []
    for _ in range(repeats):
        started, started_cpu = time.perf_counter(), time.process_time()
        result = estimator.estimate(problem)
        totals.append(time.perf_counter() - started)
        cpu.append(time.process_time() - started_cpu)
        stages.append([stage.seconds for stage in result.stages])
    return {
        "n": n_points,
        "total_s": float(np.median(totals)),
        "cpu_s": float(np.median(cpu)),
        "stage_s": [float(s) for s in np.median(stages, axis=0)],
        "iterations": [stage.iterations for stage in result.stages[1:]],
        "status": "/".join(stage.status for stage in result.stages[1:]),
        "active": result.stages[-1].active_points,
        "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9,
    }


def filter_seconds(dense: bool, repeats: int) -> tuple[float, list[int]]:
    """Median wall time of Stages 1-2 (:func:`fuse`) at ``DENSE_N`` points and the
    iterations, with the dense or the structured covariance."""
    estimator = IekfEstimator()
    p = estimator.params
    window = (p.window_along_normal_m, p.window_across_normal_m)
    fusion = fusion_problem(cylinder_problem(DENSE_N), p, estimator.name, window, p.facing_filter)
    model = {"covariance_model": DenseCovariance} if dense else {}
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        outcomes = fuse(fusion, estimator.settings(), **model)
        times.append(time.perf_counter() - started)
    return float(np.median(times)), [outcome.iterations for outcome in outcomes]


def in_fresh_process(n_points: int) -> dict:
    command = [sys.executable, __file__, "--points", str(n_points)]
    done = subprocess.run(command, check=True, capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, help="(internal) one row, as JSON")
    args = parser.parse_args()
    if args.points:
        print(json.dumps(estimate_row(args.points, REPEATS.get(args.points, 3))))
        return

    print("iekf estimate, Stages 0-2 with set-up and self-diagnosis, one thread, wall time;")
    print(f"median of {', '.join(f'{r} at {n:,}' for n, r in REPEATS.items())} runs")
    header = (
        f"{'N':>9} {'total s':>8} {'target':>7} {'cpu s':>6} {'S0 / S1 / S2 s':>20} {'iters':>6} "
        f"{'|A|':>6} {'peak GB':>8}  status"
    )
    print(header)
    print("-" * len(header))
    rows = []
    for n_points, target in TARGETS_S.items():
        row = in_fresh_process(n_points)
        rows.append(row)
        stages = " / ".join(f"{s:.3f}" for s in row["stage_s"])
        iterations = "+".join(str(i) for i in row["iterations"])
        print(
            f"{n_points:>9,} {row['total_s']:>8.3f} {target:>7.2f} {row['cpu_s']:>6.3f} "
            f"{stages:>20} {iterations:>6} {row['active']:>6} {row['peak_gb']:>8.2f}  "
            f"{row['status']}"
        )
        record(
            f"estimator, Stages 0-2 with set-up, N = {n_points:,}, one thread "
            f"(iterations {iterations}; cpu {row['cpu_s']:.2f} s)",
            row["total_s"],
            "s",
            target,
        )
    print()
    print("growth with N (time ratio for the ratio of points):")
    for small, large in itertools.pairwise(rows):
        n_ratio = large["n"] / small["n"]
        t_ratio = large["total_s"] / small["total_s"]
        print(
            f"  {small['n']:>9,} -> {large['n']:>9,}: {n_ratio:>4.0f}x points, {t_ratio:.2f}x time"
        )
    largest = rows[-1]
    record(
        f"estimator: time growth {rows[-2]['n']:,} -> {largest['n']:,} points "
        f"({largest['n'] / rows[-2]['n']:.0f}x)",
        largest["total_s"] / rows[-2]["total_s"],
        "x",
    )
    record(
        f"estimator: peak memory of the process, N = {largest['n']:,}",
        largest["peak_gb"],
        "GB",
        MEMORY_TARGET_GB,
    )

    structured, structured_iterations = filter_seconds(False, 5)
    dense, dense_iterations = filter_seconds(True, DENSE_REPEATS)
    ratio = dense / structured
    print()
    print(
        f"Stages 1-2 at N = {DENSE_N:,}: structured {structured:.4f} s "
        f"(iterations {structured_iterations}), dense {dense:.3f} s (iterations "
        f"{dense_iterations}): {ratio:.1f}x"
    )
    record(
        f"estimator: dense / structured IEKF, Stages 1-2, N = {DENSE_N:,}",
        ratio,
        "x",
        DENSE_RATIO_TARGET,
        at_most=False,
    )


if __name__ == "__main__":
    main()
