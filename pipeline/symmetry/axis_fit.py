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

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from pipeline.metrics import MAD_TO_SIGMA
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
    u, v = probe.across_axes()
    relative = points - centroid
    x, y = relative @ u, relative @ v
    # Kasa's algebraic circle: x^2 + y^2 = 2 a x + 2 b y + c, linear in (a, b, c).
    design = np.column_stack([2.0 * x, 2.0 * y, np.ones_like(x)])
    (a, b, _), *_ = np.linalg.lstsq(design, x**2 + y**2, rcond=None)
    start = np.clip([a, b], -reach, reach)

    def residuals(across: np.ndarray) -> np.ndarray:
        point = centroid + across[0] * u + across[1] * v
        return profile_residuals(points, probe.direction, point, slice_m, min_points)

    along = relative @ probe.direction
    counts = np.bincount(np.floor((along - along.min()) / slice_m).astype(np.int64))
    slices = int(np.count_nonzero(counts >= min_points))
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
