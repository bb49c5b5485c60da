"""A rotation axis from one view of a body of revolution: circle fits of slices.

The cloud is cut into slices across a candidate axis; in each slice the points' distances
from the axis should all be the slice's radius (the profile ``r(t)`` along the axis may
change from slice to slice: a bottle's neck, a cup's taper). The axis is the one whose
slices are the most nearly circles: least squares over its two across coordinates of every
point's distance from the axis minus its slice's mean, with a robust loss (the top face
seen from above shares the top slice with the rim). A flat face is a circle of infinite
radius, so the axis is kept within the cloud's own extent of its centroid: farther than
that, the view cannot tell.

Pure numeric: ``(N, 3)`` points in frame R (m) in, :class:`AxisFit` out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from pipeline.metrics import MAD_TO_SIGMA
from pipeline.symmetry.search import half_sphere
from pipeline.types import Symmetry

#: Points the fit uses at most (an even subsample of the cloud's order).
FIT_POINTS = 800
#: Residuals beyond this scale (m) count less than quadratically in the fit: the top face
#: seen from above shares its slice with the rim, at every radius from 0 to the rim's.
ROBUST_SCALE_M = 0.002
#: The slices' thickness along the axis (m).
SLICE_M = 0.01
#: The axis of an object standing on the table.
UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class AxisFit:
    """The axis found and how well the view's slices fit circles about it.

    Attributes:
        axis: the ``"axis"`` symmetry, frame R.
        profile_rms_m: robust RMS (1.4826 x the median absolute value) of the points'
            distances from the axis about their slice's mean (m): the sensor's noise on a
            body of revolution, more on anything else.
        slices: the slices that held enough points.
    """

    axis: Symmetry
    profile_rms_m: float
    slices: int


def profile_residuals(
    points_m: np.ndarray,
    direction: np.ndarray,
    point_m: np.ndarray,
    slice_m: float,
    min_points: int,
) -> np.ndarray:
    """Each point's distance from the axis minus the mean distance of its slice (m); the
    points of slices with fewer than ``min_points`` are left out."""
    relative = points_m - point_m
    along = relative @ direction
    radius = np.linalg.norm(relative - along[:, None] * direction[None, :], axis=1)
    slices = np.floor((along - along.min()) / slice_m).astype(np.int64)
    counts = np.bincount(slices)
    kept = counts[slices] >= min_points
    means = np.bincount(slices, weights=radius) / np.maximum(counts, 1)
    return (radius - means[slices])[kept]


def fit_axis(
    points_m: np.ndarray,
    direction: np.ndarray = UP,
    *,
    slice_m: float = SLICE_M,
    min_points: int = 12,
) -> AxisFit | None:
    """The axis along ``direction`` (default +z: an object standing on the table) whose
    slices of ``points_m`` are the most nearly circles, or None when fewer than three
    slices hold ``min_points`` points.

    Args:
        slice_m: the slices' thickness along the axis (m).
    """
    points = np.asarray(points_m, dtype=np.float64)
    points = points[:: max(1, len(points) // FIT_POINTS)]
    reach = float(np.max(np.ptp(points, axis=0)))
    return _fit_across(points, direction, points.mean(axis=0), reach, slice_m, min_points)


def _fit_across(
    points: np.ndarray,
    direction: np.ndarray,
    centroid: np.ndarray,
    reach: float,
    slice_m: float,
    min_points: int,
) -> AxisFit | None:
    """The best axis along ``direction``: least squares over its two across coordinates,
    started at the algebraic circle fit of the points projected across it."""
    probe = Symmetry("axis", direction, centroid)
    u, v, start = _kasa_centre(points, probe.direction, centroid, reach)
    relative = points - centroid

    def residuals(across: np.ndarray) -> np.ndarray:
        point = centroid + across[0] * u + across[1] * v
        return profile_residuals(points, probe.direction, point, slice_m, min_points)

    slices = _slice_count(relative, probe.direction, slice_m, min_points)
    if slices < 3:
        return None
    solved = least_squares(
        residuals,
        start,
        bounds=([-reach, -reach], [reach, reach]),
        loss="soft_l1",
        f_scale=ROBUST_SCALE_M,
    )
    point = centroid + solved.x[0] * u + solved.x[1] * v
    spread = MAD_TO_SIGMA * float(np.median(np.abs(residuals(solved.x))))
    return AxisFit(Symmetry("axis", probe.direction, point), spread, slices)


#: Directions of the coarse search over the half sphere (mean spacing ``sqrt(2 pi / n)``:
#: 14 deg), besides +z and the cloud's principal axes.
COARSE_DIRECTIONS = 100
#: Coarse directions refined (the best that lie at least :data:`DISTINCT_RAD` apart).
REFINED_DIRECTIONS = 3
#: Two candidate directions closer than this are one (rad).
DISTINCT_RAD = math.radians(15.0)
#: The largest turn of the direction in one refinement (rad): a coarse neighbour's spacing
#: and more.
MAX_TURN_RAD = 0.5


def fit_any_axis(
    points_m: np.ndarray,
    *,
    slice_m: float = SLICE_M,
    min_points: int = 12,
) -> AxisFit | None:
    """The axis of any direction whose slices of ``points_m`` are the most nearly circles
    (an object lying on its side has its axis level), or None when no direction has three
    slices of ``min_points`` points.

    Candidate directions: +z, the cloud's three principal axes and a Fibonacci lattice of
    :data:`COARSE_DIRECTIONS` over the half sphere, each scored by the profile RMS about
    the algebraic circle fit of the points projected across it. The best
    :data:`REFINED_DIRECTIONS` distinct ones are refined by least squares over the
    direction and the axis' two across coordinates (twice, the points re-sliced along the
    direction found), and the fit with the least profile RMS is returned. As in
    :func:`fit_axis`, only the seen arc of each slice is fitted (the table hides the rest
    of a lying body).
    """
    points = np.asarray(points_m, dtype=np.float64)
    points = points[:: max(1, len(points) // FIT_POINTS)]
    centroid = points.mean(axis=0)
    reach = float(np.max(np.ptp(points, axis=0)))
    _, principal = np.linalg.eigh(np.cov((points - centroid).T))
    candidates = np.vstack([UP, principal.T, half_sphere(COARSE_DIRECTIONS)])
    coarse = np.array(
        [_coarse_rms(points, d, centroid, reach, slice_m, min_points) for d in candidates]
    )
    starts: list[np.ndarray] = []
    for index in np.argsort(coarse, kind="stable"):
        if not np.isfinite(coarse[index]) or len(starts) == REFINED_DIRECTIONS:
            break
        direction = candidates[index]
        if all(abs(direction @ start) < math.cos(DISTINCT_RAD) for start in starts):
            starts.append(direction)
    fits = []
    for start in starts:
        u, v, (a, b) = _kasa_centre(points, start, centroid, reach)
        direction, point = start, centroid + a * u + b * v
        for _ in range(2):
            direction, point = _refine(points, direction, point, reach, slice_m, min_points)
        spread = MAD_TO_SIGMA * float(
            np.median(np.abs(profile_residuals(points, direction, point, slice_m, min_points)))
        )
        axis = Symmetry("axis", direction, point)
        fits.append(AxisFit(axis, spread, _slice_count(points, direction, slice_m, min_points)))
    fits = [fit for fit in fits if fit.slices >= 3]
    return min(fits, key=lambda fit: fit.profile_rms_m) if fits else None


def tilt_deg(axis: Symmetry) -> float:
    """The angle between the axis and the vertical (deg)."""
    return math.degrees(math.acos(min(1.0, abs(float(axis.direction[2])))))


def _slice_count(points: np.ndarray, direction: np.ndarray, slice_m: float, min_points: int) -> int:
    """How many slices across ``direction`` hold at least ``min_points`` points."""
    along = points @ direction
    counts = np.bincount(np.floor((along - along.min()) / slice_m).astype(np.int64))
    return int(np.count_nonzero(counts >= min_points))


def _kasa_centre(points: np.ndarray, direction: np.ndarray, centroid: np.ndarray, reach: float):
    """The algebraic circle fit's centre of the points projected across ``direction``:
    ``(u, v, (a, b))``, the across axes and the centre's coordinates along them from the
    centroid, kept within ``reach``."""
    u, v = Symmetry("axis", direction, centroid).across_axes()
    relative = points - centroid
    x, y = relative @ u, relative @ v
    # Kasa's algebraic circle: x^2 + y^2 = 2 a x + 2 b y + c, linear in (a, b, c).
    design = np.column_stack([2.0 * x, 2.0 * y, np.ones_like(x)])
    (a, b, _), *_ = np.linalg.lstsq(design, x**2 + y**2, rcond=None)
    return u, v, np.clip([a, b], -reach, reach)


def _coarse_rms(points, direction, centroid, reach, slice_m, min_points) -> float:
    """Profile RMS about the algebraic circle fit across ``direction`` (inf with fewer than
    three slices)."""
    if _slice_count(points, direction, slice_m, min_points) < 3:
        return math.inf
    u, v, (a, b) = _kasa_centre(points, direction, centroid, reach)
    residuals = profile_residuals(points, direction, centroid + a * u + b * v, slice_m, min_points)
    return MAD_TO_SIGMA * float(np.median(np.abs(residuals)))


def _refine(points, direction, point, reach, slice_m, min_points):
    """``(direction, point)`` after least squares over the direction's turn and the axis'
    across coordinates (within ``reach`` of ``point``), the points' slices along the
    starting direction held fixed (so the residuals are continuous in the parameters)."""
    u, v = Symmetry("axis", direction, point).across_axes()
    along = (points - point) @ direction
    slices = np.floor((along - along.min()) / slice_m).astype(np.int64)
    counts = np.bincount(slices)
    kept = counts[slices] >= min_points
    points, slices = points[kept], slices[kept]
    counts = np.maximum(np.bincount(slices), 1)

    def build(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        turned = direction + x[0] * u + x[1] * v
        return turned / np.linalg.norm(turned), point + x[2] * u + x[3] * v

    def residuals(x: np.ndarray) -> np.ndarray:
        d, p = build(x)
        relative = points - p
        radius = np.linalg.norm(relative - (relative @ d)[:, None] * d[None, :], axis=1)
        means = np.bincount(slices, weights=radius) / counts
        return radius - means[slices]

    turn = math.tan(MAX_TURN_RAD)
    solved = least_squares(
        residuals,
        np.zeros(4),
        bounds=([-turn, -turn, -reach, -reach], [turn, turn, reach, reach]),
        loss="soft_l1",
        f_scale=ROBUST_SCALE_M,
    )
    return build(solved.x)
