"""Estimator benchmark: structured IEKF at N = 20k / 100k points, dense reference at 1.5k.

Run: ``python bench/estimator.py``. Single-threaded BLAS (set below, before numpy loads).
``time s`` is Stages 1 and 2 of the filter; ``diag s`` the self-diagnosis of the three
stages after it (taxel check only: the bench has no depth image).
Input: the visible half of a 40 mm radius, 100 mm tall cylinder, sampled uniformly, grasped
by two opposed 6 x 14 taxel pads (the taxels within 0.6 mm of the surface touch), with a
3 mm / 1.7 deg bias and an 8 mm / 4.6 deg plane error; ``iekf`` plugin defaults.
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import time  # noqa: E402

import numpy as np  # noqa: E402
from summary import record  # noqa: E402

from pipeline.estimation.dense import DenseCovariance  # noqa: E402
from pipeline.estimation.geometry import apply_bias  # noqa: E402
from pipeline.estimation.iekf import fuse  # noqa: E402
from pipeline.estimation.problem import estimate_result  # noqa: E402
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
TARGETS_S = {20_000: 0.3, 100_000: 1.0}
REPEATS, DENSE_REPEATS = 5, 1


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


def run(n_points: int, dense: bool, repeats: int) -> tuple[float, float, str, int, int]:
    """Median wall times of ``repeats`` fusions of the same problem and of their
    self-diagnosis (the three stages' consistency tests), and the last outcome."""
    estimator = IekfEstimator()
    settings = estimator.settings()
    fusion = estimator.fusion_problem(cylinder_problem(n_points))
    model = {"covariance_model": DenseCovariance} if dense else {}
    times, diagnosis = [], []
    for _ in range(repeats):
        started = time.perf_counter()
        outcomes = fuse(fusion, settings, **model)
        fused = time.perf_counter()
        result = estimate_result(fusion, outcomes, fused, None, estimator.consistency_settings())
        times.append(fused - started)
        diagnosis.append(time.perf_counter() - fused)
    statuses = "/".join(s.status for s in result.stages[1:])
    iterations = sum(o.iterations for o in outcomes)
    active = outcomes[-1].active_points
    return float(np.median(times)), float(np.median(diagnosis)), statuses, iterations, active


def main() -> None:
    print(
        f"Stage 1 + Stage 2 wall time, one core, iekf defaults (hybrid schedule); median of "
        f"{REPEATS} runs ({DENSE_REPEATS} for dense)"
    )
    header = (
        f"{'covariance':<11}{'N':>8}{'time s':>9}{'target s':>10}{'diag s':>8}{'iters':>7}"
        f"{'|A|':>7}  status"
    )
    print(header)
    print("-" * len(header))
    rows = [
        ("structured", 1_500),
        ("dense", 1_500),
        ("structured", 20_000),
        ("structured", 100_000),
    ]
    times = {}
    for kind, n in rows:
        dense = kind == "dense"
        repeats = DENSE_REPEATS if dense else REPEATS
        seconds, diagnosis, status, iterations, active = run(n, dense, repeats)
        times[(kind, n)] = seconds
        target = f"{TARGETS_S[n]:.2f}" if n in TARGETS_S and kind == "structured" else "-"
        print(
            f"{kind:<11}{n:>8}{seconds:>9.3f}{target:>10}{diagnosis:>8.3f}{iterations:>7}"
            f"{active:>7}  {status}"
        )
        if kind == "structured" and n in TARGETS_S:
            record(f"estimator, Stages 1-2, N = {n}, one thread", seconds, "s", TARGETS_S[n])
    ratio = times[("dense", 1_500)] / times[("structured", 1_500)]
    print(f"dense / structured at N = 1500: {ratio:.1f}x")


if __name__ == "__main__":
    main()
