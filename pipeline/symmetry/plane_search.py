"""VC beyond the vertical: the mirror plane of any orientation one view supports best.

The paper's VC searches vertical planes only (their normal level). An object lying on the
table (a spray bottle on its side, a mug on its side) may have no vertical mirror plane:
its plane leans, or lies level. This search scores planes of every orientation the way VC
scores its vertical ones, by what the camera says about their mirror images:

* a hypothesis ``{p : n . p = d}`` mirrors an even sample of the view's points
  (:data:`CHECK_POINTS`); a mirrored point *violates* when it lies more than the tolerance
  in front of the surface the camera measured on its ray (seen free space), or more than the
  tolerance below the table top (the object rests on it);
* the normals are a Fibonacci lattice over the half sphere (:data:`COARSE_NORMALS`, about
  8 deg apart; a plane's normal has no sign), each with :data:`OFFSETS` offsets across
  ``max_offset_m`` of the points' centroid; the hypotheses with fewest violations, then the
  most compact completion (the points' mean distance from the plane: between hypotheses the
  camera cannot tell apart, the smallest object that explains the view), are kept;
* the best few local minima over the lattice are refined twice on a finer local grid of
  normals (half the spacing, then a quarter) and offsets (a fifth of the step, then a
  tenth): coarse to fine, as the mesh search (:mod:`pipeline.symmetry.search`).

Pure numeric but for the depth image it is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.perception.visibility import free_space_depths
from pipeline.symmetry.search import half_sphere, local_minima
from pipeline.types import DepthObservation, Symmetry

#: Normals of the coarse lattice over the half sphere (mean spacing ``sqrt(2 pi / n)``:
#: 8.3 deg).
COARSE_NORMALS = 300
#: Offsets per normal, evenly over ``+-max_offset_m`` about the centroid (inclusive).
OFFSETS = 13
#: Local minima of the coarse lattice refined.
REFINED_STARTS = 4
#: Points of the view (an even subsample) each hypothesis mirrors.
CHECK_POINTS = 250


@dataclass(frozen=True)
class PlaneFit:
    """The best mirror plane of any orientation for a view.

    Attributes:
        symmetry: the plane (kind ``"plane"``, or ``"vertical-plane"`` when its normal is
            level to 1e-9), frame R.
        violation_share: share of the mirrored check sample that violates (-).
    """

    symmetry: Symmetry
    violation_share: float


def violation_counts(
    points_m: np.ndarray,
    normals: np.ndarray,
    offsets_m: np.ndarray,
    view: DepthObservation,
    tolerance_m: float,
    table_z_m: float,
) -> np.ndarray:
    """``(H,)`` how many of ``points_m`` (``(N, 3)``, frame R) each plane
    ``{p : normals[h] . p = offsets_m[h]}`` mirrors into seen free space or below the
    table (each by more than ``tolerance_m``)."""
    signed = points_m @ normals.T - offsets_m[None, :]  # (N, H)
    mirrored = points_m[None, :, :] - 2.0 * signed.T[:, :, None] * normals[:, None, :]
    flat = mirrored.reshape(-1, 3)
    in_free_space = (
        free_space_depths(flat, view.depth_m, view.intrinsics, view.T_robot_camera) > tolerance_m
    )
    below = flat[:, 2] < table_z_m - tolerance_m
    return (in_free_space | below).reshape(len(normals), -1).sum(axis=1)


def table_top(points_m: np.ndarray, view: DepthObservation) -> float:
    """The table top's z in frame R: the view's, else the lowest point of the cloud."""
    if view.table_height_m is not None:
        return float(view.table_height_m)
    return float(np.min(points_m[:, 2]))


def _ranked(
    sample: np.ndarray,
    normals: np.ndarray,
    offsets_m: np.ndarray,
    view: DepthObservation,
    tolerance_m: float,
    table_z_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Violation counts and spreads of the hypotheses, and their order (best first)."""
    counts = violation_counts(sample, normals, offsets_m, view, tolerance_m, table_z_m)
    spread = np.abs(sample @ normals.T - offsets_m[None, :]).mean(axis=0)
    return counts, spread, np.lexsort((spread, counts))


def _local_normals(normal: np.ndarray, step_rad: float) -> np.ndarray:
    """``(9, 3)`` ``normal`` and eight neighbours ``step_rad`` away around it."""
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    turns = np.arange(8) * math.pi / 4.0
    ring = math.cos(step_rad) * normal[None, :] + math.sin(step_rad) * (
        np.cos(turns)[:, None] * u + np.sin(turns)[:, None] * v
    )
    return np.vstack([normal, ring])


def best_plane(
    points_m: np.ndarray,
    view: DepthObservation,
    *,
    tolerance_m: float,
    max_offset_m: float,
) -> PlaneFit:
    """The mirror plane of any orientation whose mirror image of the view the camera
    refutes least (module doc).

    Args:
        points_m: ``(N, 3)`` the object's points, frame R.
        view: the depth image they came from (its believed camera pose).
        tolerance_m: how far in front of the measured surface, or below the table, a
            mirrored point may lie (m).
        max_offset_m: the largest plane shift from the centroid along the normal (m).
    """
    points = np.asarray(points_m, dtype=np.float64)
    sample = points[:: max(1, len(points) // CHECK_POINTS)]
    centroid = points.mean(axis=0)
    table_z = table_top(points, view)
    lattice = half_sphere(COARSE_NORMALS)
    shifts = np.linspace(-max_offset_m, max_offset_m, OFFSETS)
    normals = np.repeat(lattice, OFFSETS, axis=0)
    offsets = normals @ centroid + np.tile(shifts, len(lattice))
    counts, spread, _ = _ranked(sample, normals, offsets, view, tolerance_m, table_z)
    # Each normal's best offset, then the normals no neighbour beats.
    per_normal = (counts + spread / (1.0 + spread.max())).reshape(len(lattice), OFFSETS)
    best_offset = per_normal.argmin(axis=1)
    starts = local_minima(lattice, per_normal.min(axis=1))[:REFINED_STARTS]
    step_rad = math.sqrt(2.0 * math.pi / COARSE_NORMALS)
    step_m = shifts[1] - shifts[0] if OFFSETS > 1 else max_offset_m
    candidates = []
    for start in starts:
        normal = lattice[start]
        offset = float(normal @ centroid + shifts[best_offset[start]])
        for fraction in (0.5, 0.25):
            local = _local_normals(normal, fraction * step_rad)
            # The offset through the same point of the plane for every local normal.
            anchor = centroid + (offset - normal @ centroid) * normal
            fine = np.linspace(-2.0, 2.0, 5) * fraction * 0.4 * step_m
            trial_normals = np.repeat(local, len(fine), axis=0)
            trial_offsets = trial_normals @ anchor + np.tile(fine, len(local))
            c, s, order = _ranked(sample, trial_normals, trial_offsets, view, tolerance_m, table_z)
            normal, offset = trial_normals[order[0]], float(trial_offsets[order[0]])
            best = (int(c[order[0]]), float(s[order[0]]))
        candidates.append((best, normal, offset))
    (count, _), normal, offset = min(candidates, key=lambda item: item[0])
    if normal[2] < 0.0:
        normal, offset = -normal, -offset
    kind = "vertical-plane" if abs(normal[2]) < 1e-9 else "plane"
    return PlaneFit(Symmetry(kind, normal, normal * offset), count / len(sample))
