"""Estimator benchmark: the ``iekf`` estimator at N = 20k / 100k / 1M points from a suite of
starts (:data:`STARTS`), Stages 0-2 in total, and the dense reference IEKF against the
structured one at N = 1,500.

Run: ``python bench/estimator.py``. Single-threaded BLAS (set below, before numpy loads).
Every structured row runs in a fresh process (``--points N``), warmed up on a small problem
first, so its peak memory (``ru_maxrss``) is that of one estimate at that size.

``total s`` is the whole :meth:`IekfEstimator.estimate` call, what a user waits for and what
the result's stage times add up to: Stage 0 (the set-up: the kernel's arrays and the point
index), Stages 1 and 2, and the self-diagnosis of the three stages (taxel check only: the
bench has no depth image); ``target`` its wall-time target (:data:`TARGETS_S`; ``-``: none
at 20,000 points); ``cpu s`` is its processor time (less sensitive to a busy machine) and
``S0 / S1 / S2`` the stages' own wall times (each with its share of the diagnosis).
``iters`` are Stage 1's and Stage 2's iteration counts and ``s/iter`` the time of Stages 1-2
per iteration (``x easy``: over the easy start's at the same N), so a faster row cannot
come from stopping early or from an easy start. The dense / structured
ratio compares Stages 1-2 (the filter itself, the only part the covariance model changes)
in the same process.

``--baseline DIR`` times another source tree beside this one (e.g. main: ``git archive main |
tar -x -C DIR``): every row is estimated in turn in a fresh process importing DIR's
``pipeline`` and ``plugins`` and in one importing this tree's, and ``x base`` is this tree's
processor time over the baseline's (on a busy machine the ratio of processor times measured
in turn says more than either wall time).

Input: the visible half of a 40 mm radius, 100 mm tall cylinder, sampled uniformly, grasped
by 6 x 14 taxel pads (the taxels within 0.6 mm of the surface touch); ``iekf`` plugin
defaults. Starts: ``easy``, two opposed pads, a 3 mm / 1.7 deg bias and an 8 mm / 4.6 deg
plane error; ``plane 45 deg / 30 mm``, the corner of the paper's Fig. 8 claim region;
``bias 25 mm``, two pads, the plane 20 deg / 10 mm off; ``three pads, bias 35 mm``, pads
120 deg apart with one on the camera's side, the plane 30 deg / 12 mm off; ``two pads, bias
35 mm``, two jaws beyond their reach (30 deg to the jaws' line), the plane 20 deg / 10 mm off.
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
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from summary import record  # noqa: E402

import pipeline  # noqa: E402
from pipeline.estimation.dense import DenseCovariance  # noqa: E402
from pipeline.estimation.geometry import apply_bias  # noqa: E402
from pipeline.estimation.iekf import fuse  # noqa: E402
from pipeline.estimation.map_params import fusion_problem  # noqa: E402
from pipeline.geometry.poses import rotation_z  # noqa: E402
from pipeline.types import (  # noqa: E402
    Bias,
    Contacts,
    EstimationProblem,
    PointCloud,
    SymmetryInit,
    SymmetryPlane,
)
from plugins.estimators.iekf import IekfEstimator  # noqa: E402

RADIUS_M, HEIGHT_M, PITCH_M = 0.04, 0.10, 0.0034
#: The cloud sizes timed for every start.
SIZES = (20_000, 100_000, 1_000_000)
#: Wall-time targets of the whole estimate (Stages 0-2, set-up included), one thread, for
#: every start (issue 44); 20,000 points has none (docs/performance.md, "The 20,000-point
#: rows").
TARGETS_S = {100_000: 0.6, 1_000_000: 5.0}
#: Peak resident memory of the process estimating the largest cloud.
MEMORY_TARGET_GB = 2.0
DENSE_RATIO_TARGET = 100.0
#: No start may take more than this times the easy start's time per iteration.
PER_ITERATION_RATIO_TARGET = 2.0
REPEATS = {20_000: 5, 100_000: 5, 1_000_000: 2}
DENSE_N, DENSE_REPEATS = 1_500, 1


@dataclass(frozen=True)
class Start:
    """One start of the suite: the hand, the true bias and the initial plane's error.

    Attributes:
        pad_azimuths_deg: where the pads touch, about the axis (180: the camera's side).
        bias: true ``(b_theta, b_x, b_y, b_z)`` (rad, m).
        plane_error: the initial plane's ``(theta, r)`` error (rad, m).
    """

    name: str
    pad_azimuths_deg: tuple[float, ...]
    bias: tuple[float, float, float, float]
    plane_error: tuple[float, float]


_PARALLEL = (180.0, 0.0)
_THREE = (180.0, 300.0, 60.0)
STARTS = {
    start.name: start
    for start in (
        Start("easy", _PARALLEL, (0.03, 0.003, -0.002, 0.001), (0.08, 0.008)),
        # The corner of the paper's Fig. 8 claim region: theta 45 deg, |r| 30 mm.
        Start("plane 45 deg / 30 mm", _PARALLEL, (0.03, 0.003, -0.002, 0.001), (0.785, 0.03)),
        # Two jaws at the paper's parallel reach and beyond, the plane 20 deg / 10 mm off.
        Start("bias 25 mm", _PARALLEL, (0.0, 0.0177, 0.0177, 0.0), (0.35, 0.01)),
        # Three pads, one on the camera's side, 35 mm bias, plane 30 deg / 12 mm off.
        Start("three pads, bias 35 mm", _THREE, (0.0, -0.0175, 0.0303, 0.0), (0.52, -0.012)),
        # Two jaws beyond their reach, 35 mm at 30 deg to the jaws' line; plane 20 deg / 10 mm off.
        Start("two pads, bias 35 mm", _PARALLEL, (0.0, -0.0303, 0.0175, 0.0), (0.35, -0.01)),
    )
}


def cylinder_problem(n_points: int, start: Start, seed: int = 0) -> EstimationProblem:
    """The visible half of the cylinder (axis at the origin, camera at -x) and the taxels of
    ``start``'s pads that lie within 0.6 mm of the surface, moved by its bias."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(np.pi / 2, 3 * np.pi / 2, n_points)
    points = np.column_stack(
        [RADIUS_M * np.cos(angle), RADIUS_M * np.sin(angle), rng.uniform(0, HEIGHT_M, n_points)]
    )
    points += rng.normal(0.0, 0.0005, points.shape)
    g_true = np.array([*start.bias, 0.0, 0.0])
    pivot = points.mean(axis=0)
    col, row = np.meshgrid((np.arange(6) - 2.5) * PITCH_M, (np.arange(14) - 6.5) * PITCH_M)
    touching = (RADIUS_M - np.sqrt(RADIUS_M**2 - col**2) < 0.0006).ravel()
    taxels, normals, pads = [], [], []
    for k, azimuth in enumerate(np.radians(start.pad_azimuths_deg)):
        outward = np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
        tangent = np.array([-outward[1], outward[0], 0.0])
        grid = (
            RADIUS_M * outward
            + col.ravel()[:, None] * tangent
            + (row.ravel()[:, None] + HEIGHT_M / 2) * np.array([0.0, 0.0, 1.0])
        )[touching]
        taxels.append(apply_bias(grid, g_true, pivot))
        normals.append(np.tile(-outward, (len(grid), 1)) @ rotation_z(g_true[0]).T)
        pads.append(np.full(len(grid), f"pad{k}"))
    contacts = Contacts(
        positions=np.concatenate(taxels),
        normals=np.concatenate(normals),
        pads=np.concatenate(pads),
        taxel_indices=np.arange(sum(len(t) for t in taxels)),
    )
    theta, r = start.plane_error
    init = SymmetryInit(plane=SymmetryPlane(theta_rad=theta, offset_m=r), bias=Bias())
    return EstimationProblem(cloud=PointCloud(points), init=init, grasps=(contacts,))


def estimate_row(n_points: int, start: Start, repeats: int) -> dict:
    """Median wall time of ``repeats`` whole estimates of the N-point problem, its stages'
    median times, the last run's iterations and statuses, and this process's peak memory."""
    estimator = IekfEstimator()
    estimator.estimate(cylinder_problem(DENSE_N, start, seed=1))  # imports, first calls
    problem = cylinder_problem(n_points, start)
    totals, cpu, stages = [], [], []
    for _ in range(repeats):
        started, started_cpu = time.perf_counter(), time.process_time()
        result = estimator.estimate(problem)
        totals.append(time.perf_counter() - started)
        cpu.append(time.process_time() - started_cpu)
        stages.append([stage.seconds for stage in result.stages])
    stage_s = [float(s) for s in np.median(stages, axis=0)]
    iterations = [stage.iterations for stage in result.stages[1:]]
    return {
        "n": n_points,
        "start": start.name,
        "total_s": float(np.median(totals)),
        "cpu_s": float(np.median(cpu)),
        "stage_s": stage_s,
        "iterations": iterations,
        "per_iteration_s": sum(stage_s[1:]) / max(sum(iterations), 1),
        "status": "/".join(stage.status for stage in result.stages[1:]),
        "active": result.stages[-1].active_points,
        "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9,
        "tree": str(Path(pipeline.__file__).resolve().parents[1]),
    }


def filter_seconds(dense: bool, repeats: int) -> tuple[float, list[int]]:
    """Median wall time of Stages 1-2 (:func:`fuse`) at ``DENSE_N`` points and the
    iterations, with the dense or the structured covariance."""
    estimator = IekfEstimator()
    p = estimator.params
    window = (p.window_along_normal_m, p.window_across_normal_m)
    problem = cylinder_problem(DENSE_N, STARTS["easy"])
    fusion = fusion_problem(problem, p, estimator.name, window, p.facing_filter)
    model = {"covariance_model": DenseCovariance} if dense else {}
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        outcomes = fuse(fusion, estimator.settings(), **model)
        times.append(time.perf_counter() - started)
    return float(np.median(times)), [outcome.iterations for outcome in outcomes]


def in_fresh_process(n_points: int, start: str, tree: Path | None = None) -> dict:
    """One row (:func:`estimate_row`) in a new process, importing ``tree``'s ``pipeline`` and
    ``plugins`` when given (this tree's otherwise)."""
    command = [sys.executable, __file__, "--points", str(n_points), "--start", start]
    environment = dict(os.environ)
    if tree is not None:
        environment["PYTHONPATH"] = os.pathsep.join(
            [str(tree), *filter(None, [environment.get("PYTHONPATH")])]
        )
    done = subprocess.run(command, check=True, capture_output=True, text=True, env=environment)
    row = json.loads(done.stdout.strip().splitlines()[-1])
    if tree is not None and Path(row["tree"]) != tree:
        raise SystemExit(f"estimator.py: error: --baseline {tree}: the row ran {row['tree']}")
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, help="(internal) one row, as JSON")
    parser.add_argument("--start", choices=sorted(STARTS), help="(internal) its start")
    parser.add_argument(
        "--baseline",
        metavar="DIR",
        type=Path,
        help="a source tree (with pipeline/ and plugins/) to time beside this one, row by row",
    )
    args = parser.parse_args()
    baseline = None
    if args.baseline is not None:
        baseline = args.baseline.resolve()
        if not (baseline / "pipeline" / "__init__.py").is_file():
            parser.error(f"--baseline {args.baseline}: no pipeline/__init__.py there")
    if args.points:
        start = STARTS[args.start or "easy"]
        print(json.dumps(estimate_row(args.points, start, REPEATS.get(args.points, 3))))
        return

    print("iekf estimate, Stages 0-2 with set-up and self-diagnosis, one thread, wall time;")
    print(f"median of {', '.join(f'{r} at {n:,}' for n, r in REPEATS.items())} runs")
    header = (
        f"{'start':>24} {'N':>9} {'total s':>8} {'target':>7} {'cpu s':>6} "
        f"{'S0 / S1 / S2 s':>20} {'iters':>6} {'s/iter':>7} {'x easy':>6} {'|A|':>6} "
        f"{'peak GB':>8}  status"
    )
    if baseline is not None:
        header += f"  {'base cpu s':>10} {'iters':>6} {'x base':>6}"
    print(header)
    print("-" * len(header))
    rows: dict[str, list[dict]] = {}
    for name in STARTS:
        for n_points in SIZES:
            target = TARGETS_S.get(n_points)
            base = None if baseline is None else in_fresh_process(n_points, name, baseline)
            row = in_fresh_process(n_points, name)
            rows.setdefault(name, []).append(row)
            easy = rows["easy"][len(rows[name]) - 1]
            ratio = row["per_iteration_s"] / easy["per_iteration_s"]
            stages = " / ".join(f"{s:.3f}" for s in row["stage_s"])
            iterations = "+".join(str(i) for i in row["iterations"])
            print(
                f"{name:>24} {n_points:>9,} {row['total_s']:>8.3f} "
                f"{'-' if target is None else f'{target:.2f}':>7} "
                f"{row['cpu_s']:>6.3f} {stages:>20} {iterations:>6} "
                f"{row['per_iteration_s']:>7.4f} {ratio:>6.2f} {row['active']:>6} "
                f"{row['peak_gb']:>8.2f}  {row['status']}"
                + (
                    ""
                    if base is None
                    else f"  {base['cpu_s']:>10.3f} "
                    f"{'+'.join(str(i) for i in base['iterations']):>6} "
                    f"{row['cpu_s'] / base['cpu_s']:>6.2f}"
                )
            )
            record(
                f"estimator, {name}, Stages 0-2 with set-up, N = {n_points:,}, one thread "
                f"(iterations {iterations}; cpu {row['cpu_s']:.2f} s)",
                row["total_s"],
                "s",
                target,
            )
            if name != "easy":
                record(
                    f"estimator, {name}: time per iteration of Stages 1-2 / the easy "
                    f"start's, N = {n_points:,}",
                    ratio,
                    "x",
                    PER_ITERATION_RATIO_TARGET,
                )
    easy_rows = rows["easy"]
    print()
    print("growth with N, easy start (time ratio for the ratio of points):")
    for small, large in itertools.pairwise(easy_rows):
        n_ratio = large["n"] / small["n"]
        t_ratio = large["total_s"] / small["total_s"]
        print(
            f"  {small['n']:>9,} -> {large['n']:>9,}: {n_ratio:>4.0f}x points, {t_ratio:.2f}x time"
        )
    largest = easy_rows[-1]
    record(
        f"estimator: time growth {easy_rows[-2]['n']:,} -> {largest['n']:,} points "
        f"({largest['n'] / easy_rows[-2]['n']:.0f}x)",
        largest["total_s"] / easy_rows[-2]["total_s"],
        "x",
    )
    record(
        f"estimator: peak memory of the process, N = {largest['n']:,}",
        max(row["peak_gb"] for start_rows in rows.values() for row in start_rows),
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
