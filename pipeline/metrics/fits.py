"""Fits that measure a completed model (docs/method.md §6): Taubin's circle (diameter of
cylinders), a robust orthogonal line (IRLS with Tukey bisquare weights) and the thickness and
side angle of a box-like object split into front and back by its symmetry plane.

Pure functions on point arrays in the robot frame ``R`` (metres, radians).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.types import Bias, SymmetryPlane

#: Tukey bisquare tuning constant: 95 % efficiency under Gaussian residuals.
TUKEY_C = 4.685


#: Scales a median absolute deviation to a Gaussian standard deviation.
MAD_TO_SIGMA = 1.4826


#: Points used to rank candidate starting lines (a random subset of larger clouds).
_MEDIAN_SAMPLE = 2000


def _as_xy(points: np.ndarray) -> np.ndarray:
    """``(N, 2)`` table-plane coordinates of ``(N, 2)`` or ``(N, 3)`` points."""
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] not in (2, 3):
        raise ValueError(f"points must have shape (N, 2) or (N, 3), got {array.shape}")
    return array[:, :2]


@dataclass(frozen=True)
class CircleFit:
    """A circle in the table plane: centre ``(x, y)`` and radius, metres."""

    centre_xy_m: np.ndarray
    radius_m: float

    @property
    def diameter_m(self) -> float:
        return 2.0 * self.radius_m


def fit_circle_taubin(points: np.ndarray) -> CircleFit:
    """Taubin's algebraic circle fit (Taubin 1991), in Chernov's SVD formulation.

    Minimises the algebraic distance ``sum (|p - c|^2 - R^2)^2`` normalised by its gradient
    (the Taubin constraint), which is nearly unbiased for arcs and needs no start value.

    Args:
        points: ``(N, 2)`` or ``(N, 3)`` points; only x and y are used (projection to the table).

    Returns:
        The fitted circle.

    Raises:
        ValueError: fewer than three points, or the points are collinear (no finite circle).
    """
    xy = _as_xy(points)
    if len(xy) < 3:
        raise ValueError(f"a circle fit needs at least 3 points, got {len(xy)}")
    mean_xy = xy.mean(axis=0)
    centred = xy - mean_xy
    z = np.einsum("ij,ij->i", centred, centred)
    z_mean = z.mean()
    if z_mean == 0.0:
        raise ValueError("a circle fit needs distinct points")
    z0 = (z - z_mean) / (2.0 * np.sqrt(z_mean))
    _, _, vt = np.linalg.svd(np.column_stack([z0, centred]), full_matrices=False)
    a0, a1, a2 = vt[2]
    a0 = a0 / (2.0 * np.sqrt(z_mean))
    if abs(a0) < 1e-12 * max(abs(a1), abs(a2)):
        raise ValueError("points are collinear: no finite circle fits them")
    a3 = -z_mean * a0
    centre = mean_xy - np.array([a1, a2]) / (2.0 * a0)
    radius = float(np.sqrt(a1 * a1 + a2 * a2 - 4.0 * a0 * a3) / (2.0 * abs(a0)))
    return CircleFit(centre_xy_m=centre, radius_m=radius)


def diameter_error(points: np.ndarray, true_diameter_m: float) -> float:
    """``|fitted diameter - true diameter|`` (m) of a cylinder's completed cloud.

    The cloud is projected to the table and fitted with :func:`fit_circle_taubin`; it should
    hold side-surface points only (cap points fill the disc and shrink the fit).
    """
    return abs(fit_circle_taubin(points).diameter_m - true_diameter_m)


def side_wall(points: np.ndarray, cap_margin_m: float = 0.006) -> np.ndarray:
    """The points of a cloud below its top cap: lower than ``cap_margin_m`` under the 98th
    percentile of height (robust to a few high outliers).

    A view from above sees a cylinder's top cap, whose points fill the disc and pull a
    circle fit inward (about 4 mm on the 53 mm salt cylinder seen from 45 deg); the diameter
    is measured on the side wall only.
    """
    points = np.asarray(points, dtype=np.float64)
    top = np.percentile(points[:, 2], 98.0)
    return points[points[:, 2] < top - cap_margin_m]


@dataclass(frozen=True)
class LineFit:
    """A line ``{point_m + t direction}`` in the table plane.

    Attributes:
        point_m: ``(2,)`` a point on the line (the weighted centroid of the inliers).
        direction: ``(2,)`` unit direction.
        weights: ``(N,)`` final bisquare weights of the input points (0 = rejected).
        scale_m: final robust residual scale (MAD-based standard deviation).
        iterations: IRLS iterations used.
    """

    point_m: np.ndarray
    direction: np.ndarray
    weights: np.ndarray
    scale_m: float
    iterations: int

    @property
    def normal(self) -> np.ndarray:
        """``(2,)`` unit normal (direction rotated by +90 degrees)."""
        return np.array([-self.direction[1], self.direction[0]])

    def distances(self, points_xy: np.ndarray) -> np.ndarray:
        """Signed orthogonal distances (m) of ``(N, 2)`` points to the line."""
        return (np.asarray(points_xy)[:, :2] - self.point_m) @ self.normal


def _median(values: np.ndarray) -> np.ndarray:
    """``np.median(values, axis=-1)`` bit for bit, for finite values, from one partition.

    numpy's median partitions at the two middle ranks and the last (its NaN check); the
    lower middle value is also the largest of the values below the upper one, so one
    partition at the upper rank and a maximum find it, at a third of the cost on the robust
    line fit's ``(200, 2000)`` residuals.
    """
    half = values.shape[-1] // 2
    part = np.partition(values, half, axis=-1)
    if values.shape[-1] % 2:
        return part[..., half]
    return (part[..., :half].max(axis=-1) + part[..., half]) / 2.0


def _weighted_orthogonal_fit(xy: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Total-least-squares line through weighted points: (centroid, unit direction)."""
    total = weights.sum()
    centroid = (weights[:, None] * xy).sum(axis=0) / total
    centred = xy - centroid
    scatter = (weights[:, None] * centred).T @ centred
    eigenvalues, eigenvectors = np.linalg.eigh(scatter)
    return centroid, eigenvectors[:, np.argmax(eigenvalues)]


def _least_median_start(xy: np.ndarray, candidates: int) -> tuple[np.ndarray, np.ndarray]:
    """Line through the point pair with the least median squared orthogonal residual.

    Pairs are drawn with a fixed seed so the fit is deterministic; with 30 % outliers and
    200 pairs the chance that no pair is outlier-free is 0.51^200, i.e. nil. Medians are
    taken over at most ``_MEDIAN_SAMPLE`` points to bound memory on dense clouds.
    """
    rng = np.random.default_rng(0)
    first = rng.integers(0, len(xy), candidates)
    second = rng.integers(0, len(xy), candidates)
    keep = first != second
    directions = xy[second[keep]] - xy[first[keep]]
    lengths = np.linalg.norm(directions, axis=1)
    keep_nonzero = lengths > 0.0
    if not np.any(keep_nonzero):
        return _weighted_orthogonal_fit(xy, np.ones(len(xy)))
    anchors = xy[first[keep]][keep_nonzero]
    directions = directions[keep_nonzero] / lengths[keep_nonzero, None]
    normals = np.column_stack([-directions[:, 1], directions[:, 0]])
    sample = xy[rng.permutation(len(xy))[:_MEDIAN_SAMPLE]]
    # One row of residuals per candidate line, so that each median partitions contiguous
    # values (the same products and differences as the columns of ``sample @ normals.T``).
    residuals = np.subtract(
        (sample @ normals.T).T, np.einsum("kj,kj->k", anchors, normals)[:, None], order="C"
    )
    best = int(np.argmin(_median(np.square(residuals, out=residuals))))
    return anchors[best], directions[best]


def fit_line_irls(
    points: np.ndarray,
    *,
    tuning: float = TUKEY_C,
    max_iterations: int = 50,
    tolerance_m: float = 1e-9,
    min_scale_m: float = 1e-6,
    start_candidates: int = 200,
) -> LineFit:
    """Robust orthogonal line fit by iteratively reweighted least squares.

    Start: the least-median-of-squares line over ``start_candidates`` random point pairs
    (fixed seed), which survives far more outliers than a least-squares start. Each iteration
    takes the orthogonal residuals ``d``, the robust scale ``s = 1.4826 MAD(d)`` (floored at
    ``min_scale_m``), Tukey bisquare weights ``w = (1 - (d / (tuning s))^2)^2`` for
    ``|d| < tuning s`` (else 0), and refits the weighted total-least-squares line.

    Args:
        points: ``(N, 2)`` or ``(N, 3)`` points; only x and y are used.
        tuning: bisquare constant in units of the robust scale.
        max_iterations: IRLS iteration cap.
        tolerance_m: stop when the line's point and direction move less than this.
        min_scale_m: lower bound on the residual scale (exact data has MAD 0).
        start_candidates: point pairs tried for the starting line.

    Raises:
        ValueError: fewer than two distinct points.
    """
    xy = _as_xy(points)
    if len(xy) < 2 or np.ptp(xy, axis=0).max() == 0.0:
        raise ValueError("a line fit needs at least 2 distinct points")
    point, direction = _least_median_start(xy, start_candidates)
    weights = np.ones(len(xy))
    scale = min_scale_m
    iterations = 0
    for iteration in range(1, max_iterations + 1):
        iterations = iteration
        normal = np.array([-direction[1], direction[0]])
        residuals = (xy - point) @ normal
        scale = max(MAD_TO_SIGMA * float(_median(np.abs(residuals))), min_scale_m)
        u = residuals / (tuning * scale)
        weights = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
        if np.count_nonzero(weights) < 2:
            break
        new_point, new_direction = _weighted_orthogonal_fit(xy, weights)
        if new_direction @ direction < 0.0:
            new_direction = -new_direction
        moved = abs((new_point - point) @ normal) + np.linalg.norm(new_direction - direction)
        point, direction = new_point, new_direction
        if moved < tolerance_m:
            break
    return LineFit(point, direction, weights, scale, iterations)


def plane_after_bias(plane: SymmetryPlane, bias: Bias) -> SymmetryPlane:
    """The symmetry plane moved by a bias: the plane of ``{f_b(p) : p on plane}``.

    The completed model ``{f_b(p_n)} U {f_mb(p_n)}`` is symmetric about this plane, not about
    ``plane`` itself, whenever the bias is non-zero.
    """
    theta = plane.theta_rad + bias.yaw_rad
    moved_normal = np.array([np.cos(theta), np.sin(theta), 0.0])
    offset = (
        plane.offset_m
        - plane.normal @ bias.pivot_m
        + moved_normal @ bias.pivot_m
        + moved_normal @ bias.translation_m
    )
    return SymmetryPlane(theta_rad=float(theta), offset_m=float(offset))


@dataclass(frozen=True)
class ThicknessFit:
    """Thickness and side angle of a box-like object (docs/method.md §6).

    Attributes:
        thickness_m: distance between the front and back lines along the line through the
            grasp centre perpendicular to their mean direction.
        angle_rad: angle between the two lines, in ``[0, pi/2]`` (0 for a true box).
        front: line fitted to the points on the positive side of the plane
            (``n . p > offset``); back: the other side.
    """

    thickness_m: float
    angle_rad: float
    front: LineFit
    back: LineFit


def box_thickness(
    points: np.ndarray, plane: SymmetryPlane, grasp_centre_xy_m: np.ndarray
) -> ThicknessFit:
    """Thickness and side angle of a box from its completed cloud.

    The cloud is projected to the table and split by the symmetry plane (in the same frame as
    the points: for a completed model use :func:`plane_after_bias`). A robust line
    (:func:`fit_line_irls`) is fitted to each part; the thickness is the distance between the
    two lines' intersections with the line through ``grasp_centre_xy_m`` along the bisector of
    their normals.

    Raises:
        ValueError: a side of the plane has fewer than two points, or the lines are
            perpendicular (no thickness is defined).
    """
    xy = _as_xy(points)
    side = xy @ plane.normal[:2] - plane.offset_m
    front_xy, back_xy = xy[side > 0.0], xy[side <= 0.0]
    if len(front_xy) < 2 or len(back_xy) < 2:
        raise ValueError(
            f"box thickness needs points on both sides of the plane "
            f"(front {len(front_xy)}, back {len(back_xy)})"
        )
    front, back = fit_line_irls(front_xy), fit_line_irls(back_xy)
    back_direction = back.direction if back.direction @ front.direction >= 0 else -back.direction
    cos_angle = float(np.clip(front.direction @ back_direction, -1.0, 1.0))
    angle = float(np.arccos(cos_angle))
    bisector = front.direction + back_direction
    bisector /= np.linalg.norm(bisector)
    across = np.array([-bisector[1], bisector[0]])
    centre = np.asarray(grasp_centre_xy_m, dtype=np.float64)[:2]
    hits = []
    for line in (front, back):
        along = across @ line.normal
        if abs(along) < 1e-12:
            raise ValueError("front and back lines are perpendicular: thickness undefined")
        hits.append(-((centre - line.point_m) @ line.normal) / along)
    return ThicknessFit(abs(hits[0] - hits[1]), angle, front, back)
