"""Planar point-to-plane registration: how far the object moved between two views.

The after-view (docs/after-view.md) sees the object where the grasp left it; registering its
visible points to the first view's cloud gives the object's planar motion since the first
view, the motion the estimator's bias holds (docs/method.md §1). The motion has the bias'
form: a yaw about the vertical through a fixed pivot ``c`` and a horizontal translation,

    D(p) = R_z(yaw) (p - c) + c + (x, y, 0),

and is found by Gauss-Newton on the point-to-plane distances of the after-view's points to
the first cloud moved by ``D`` (each first-view point carrying the normal of its local
surface), within a distance gate that shrinks to ``gate_sigmas`` times the residuals' own
spread, so points the first view never saw (or the hand's edge) drop out. Its covariance is
the Gauss-Newton one, ``sigma^2 (J^T J)^-1``, with ``sigma`` the larger of the given noise
and the inliers' RMS: it shrinks with the number of points the hand leaves visible.

Two controls make it honest on a surface seen nearly edge-on or face-on (the hand's thin
fingers): a point pairs only with a surface point whose normal agrees with its own
(``min_normal_cos``), so a face's points by an edge cannot pair with the face around the
corner; and a direction of the motion that the points fix with less information than
``min_leverage_points`` points would give at full leverage (a face-on view, where only a
few grazing points by the edges say anything across the line of sight) takes none of the
points' information: a prior governs it, or with no prior there is no registration.

Pure numeric kernel: no I/O, no simulation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from pipeline.estimation.geometry import rotation_z_derivative
from pipeline.geometry.poses import rotation_z

#: Surfaces whose normal is within this of vertical say nothing about a planar motion.
_FLAT_NORMAL_Z = 0.9


@dataclass(frozen=True)
class RegistrationSettings:
    """Control of :func:`register_planar`.

    Attributes:
        noise_std_m: std of one point-to-plane distance (m): the sensor's noise on both
            views' points; the covariance uses it or the inliers' RMS, whichever is larger.
        start_gate_m: correspondences farther apart than this are ignored at first (m):
            the largest motion expected, about three stds of the prior's.
        gate_sigmas: the gate then narrows to this many RMS of the inliers' residuals.
        min_inliers: fewer inlier points than this give no registration.
        max_iterations: Gauss-Newton iteration cap.
        tolerance_m: converged when no point of the cloud moves by more than this (m).
        neighbours: points each first-view normal is fitted to.
        min_normal_cos: a pair counts only when the first view's normal and the observed
            point's own (fitted to its ``neighbours``) agree this well, ``|n . n'|``
            (0: every pair counts, and no observed normals are fitted).
        min_leverage_points: a direction of the motion (yaw scaled by the cloud's reach)
            whose information from the points is less than this many points' at full
            leverage (``1 / sigma^2`` each) takes none of it (0: every direction keeps it).
    """

    noise_std_m: float = 0.002
    start_gate_m: float = 0.03
    gate_sigmas: float = 3.0
    min_inliers: int = 30
    max_iterations: int = 40
    tolerance_m: float = 1e-5
    neighbours: int = 12
    min_normal_cos: float = 0.0
    min_leverage_points: float = 0.0


@dataclass(frozen=True)
class PlanarRegistration:
    """The planar motion ``D`` taking the first view's cloud onto the after-view's points.

    Attributes:
        motion: ``(3,)`` ``(yaw_rad, x_m, y_m)`` about ``pivot_m``.
        covariance: ``(3, 3)`` its covariance (rad, m).
        pivot_m: ``(3,)`` the pivot of the yaw, frame R.
        inliers: after-view points inside the final gate.
        rms_m: RMS point-to-plane distance of the inliers (m).
        converged: the iteration stopped on the tolerance (not the cap) with enough inliers.
    """

    motion: np.ndarray
    covariance: np.ndarray
    pivot_m: np.ndarray
    inliers: int
    rms_m: float
    converged: bool


def surface_normals(points: np.ndarray, neighbours: int) -> np.ndarray:
    """``(N, 3)`` unit normals of ``points`` from the smallest principal axis of each
    point's ``neighbours`` nearest points (sign arbitrary: only distances along it count)."""
    count = min(neighbours, len(points))
    _, index = cKDTree(points).query(points, k=count)
    patches = points[np.asarray(index).reshape(len(points), count)]
    centred = patches - patches.mean(axis=1, keepdims=True)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    return vt[:, -1, :]


def apply_planar(points: np.ndarray, motion: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``D(p)`` for ``(N, 3)`` points."""
    shifted = (points - pivot_m) @ rotation_z(float(motion[0])).T + pivot_m
    return shifted + np.array([motion[1], motion[2], 0.0])


def invert_planar(points: np.ndarray, motion: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``D^-1(q)`` for ``(N, 3)`` points."""
    unshifted = points - pivot_m - np.array([motion[1], motion[2], 0.0])
    return unshifted @ rotation_z(float(motion[0])) + pivot_m


def planar_residuals(
    observed: np.ndarray,
    first: np.ndarray,
    normals: np.ndarray,
    motion: np.ndarray,
    pivot_m: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Point-to-plane residuals ``r_j = n'_j . (q_j - D(p_j))`` of paired points, ``n'``
    the first view's normal turned by the yaw, and their ``(M, 3)`` Jacobian over
    ``motion`` (the turning normal included)."""
    yaw = float(motion[0])
    turned = normals @ rotation_z(yaw).T
    gap = observed - apply_planar(first, motion, pivot_m)
    residuals = np.einsum("ij,ij->i", turned, gap)
    derivative = rotation_z_derivative(yaw)
    d_yaw = np.einsum("ij,ij->i", normals @ derivative.T, gap) - np.einsum(
        "ij,ij->i", turned, (first - pivot_m) @ derivative.T
    )
    return residuals, np.column_stack([d_yaw, -turned[:, 0], -turned[:, 1]])


def register_planar(
    observed: np.ndarray,
    first: np.ndarray,
    pivot_m: np.ndarray,
    settings: RegistrationSettings = RegistrationSettings(),
    normals: np.ndarray | None = None,
    prior_covariance: np.ndarray | None = None,
) -> PlanarRegistration | None:
    """The planar motion taking ``first`` (the first view's cloud, or a known surface's
    points, frame R) onto ``observed`` (the after-view's points, the same frame), from no
    motion; ``normals`` are ``first``'s (None: fitted to its neighbours).

    With ``prior_covariance`` (``(3, 3)``, of a zero-mean prior on the motion) the solve is
    the maximum a posteriori one, so a view that fixes only some directions of the motion
    leaves the others at the prior; the covariance is then the posterior's. Without it,
    None when the normal equations are singular (a view that cannot fix every direction).
    None too when fewer than ``settings.min_inliers`` points pair up.
    """
    if normals is None:
        normals = surface_normals(first, settings.neighbours)
    usable = np.abs(normals[:, 2]) < _FLAT_NORMAL_Z
    if np.count_nonzero(usable) < settings.min_inliers or len(observed) < settings.min_inliers:
        return None
    first, normals = first[usable], normals[usable]
    observed_normals = None
    if settings.min_normal_cos > 0.0:
        observed_normals = surface_normals(observed, settings.neighbours)
    tree = cKDTree(first)
    pivot_m = np.asarray(pivot_m, dtype=float)
    reach = float(np.max(np.linalg.norm(first - pivot_m, axis=1)))
    information = np.zeros((3, 3)) if prior_covariance is None else np.linalg.inv(prior_covariance)
    weight = 1.0 / settings.noise_std_m**2
    motion = np.zeros(3)
    gate_m, converged = settings.start_gate_m, False
    for _ in range(settings.max_iterations):
        paired, nearest = _pairs(tree, observed, motion, pivot_m, gate_m)
        paired &= _agree(observed_normals, normals, nearest, motion, settings.min_normal_cos)
        if np.count_nonzero(paired) < settings.min_inliers:
            return None
        residuals, jacobian = planar_residuals(
            observed[paired], first[nearest[paired]], normals[nearest[paired]], motion, pivot_m
        )
        kept = _leverage_projection(jacobian, reach, settings.min_leverage_points)
        normal_matrix = weight * kept.T @ jacobian.T @ jacobian @ kept + information
        if np.linalg.cond(normal_matrix) > 1e12:
            return None
        gradient = weight * kept.T @ jacobian.T @ residuals + information @ motion
        step = -np.linalg.solve(normal_matrix, gradient)
        motion = motion + step
        rms = float(np.sqrt(np.mean(residuals**2)))
        gate_m = max(settings.gate_sigmas * max(rms, settings.noise_std_m / 3), 1e-3)
        gate_m = min(gate_m, settings.start_gate_m)
        if abs(step[0]) * reach + float(np.hypot(step[1], step[2])) < settings.tolerance_m:
            converged = True
            break
    residuals, jacobian = planar_residuals(
        observed[paired], first[nearest[paired]], normals[nearest[paired]], motion, pivot_m
    )
    rms = float(np.sqrt(np.mean(residuals**2)))
    sigma = max(rms, settings.noise_std_m)
    kept = _leverage_projection(jacobian, reach, settings.min_leverage_points)
    covariance = np.linalg.inv(kept.T @ jacobian.T @ jacobian @ kept / sigma**2 + information)
    return PlanarRegistration(
        motion=motion,
        covariance=covariance,
        pivot_m=pivot_m,
        inliers=int(np.count_nonzero(paired)),
        rms_m=rms,
        converged=converged,
    )


def _pairs(
    tree: cKDTree,
    observed: np.ndarray,
    motion: np.ndarray,
    pivot_m: np.ndarray,
    gate_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Which observed points have a first-view point within ``gate_m`` once moved back by
    ``motion`` (``(N,)`` bool), and its index (``len(first)`` where none)."""
    distance, nearest = tree.query(
        invert_planar(observed, motion, pivot_m), distance_upper_bound=gate_m
    )
    return np.isfinite(distance), nearest


def _agree(
    observed_normals: np.ndarray | None,
    normals: np.ndarray,
    nearest: np.ndarray,
    motion: np.ndarray,
    min_cos: float,
) -> np.ndarray | bool:
    """``(N,)`` bool: each observed point's normal agrees with its pair's, turned by the
    motion's yaw, to ``|cos| >= min_cos`` (True when no observed normals are fitted)."""
    if observed_normals is None:
        return True
    turned = normals[np.minimum(nearest, len(normals) - 1)] @ rotation_z(float(motion[0])).T
    return np.abs(np.einsum("ij,ij->i", turned, observed_normals)) >= min_cos


def _leverage_projection(jacobian: np.ndarray, reach_m: float, min_points: float) -> np.ndarray:
    """``(3, 3)`` projector onto the directions of the motion the rows of ``jacobian`` fix
    with at least ``min_points`` points' information at full leverage (a unit-normal
    residual per metre of motion, the yaw counted at ``reach_m``); the identity when
    ``min_points`` is 0."""
    if min_points <= 0.0:
        return np.eye(3)
    scale = np.array([1.0 / reach_m, 1.0, 1.0])
    scaled = jacobian * scale
    values, vectors = np.linalg.eigh(scaled.T @ scaled)
    strong = vectors[:, values >= min_points]
    # Back to the motion's own coordinates: D V V^T D^-1 with D = diag(scale).
    return (strong @ strong.T) * scale[:, None] / scale[None, :]
