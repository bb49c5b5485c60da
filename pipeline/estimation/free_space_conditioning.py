"""A fused stage conditioned on the camera's free space (docs/method.md §9).

The filter fuses the taxels; the camera's free space enters only the self-diagnosis. So a
fused model can fit the taxels while its mirror image grazes the silhouette by a little
more than the free-space test allows: the stage is flagged, and vision alone is selected
although the touch fits.

The free-space test depends on the plane alone (it compares ``p`` and ``f_m(p)`` with the
image before the bias), so a flagged stage whose taxels pass is conditioned on it. Of the
planes whose model passes the free-space test, the one nearest the fused plane in the
posterior's metric (the Mahalanobis distance of the plane's marginal ``P_pp``) is taken.
The bias follows the plane by the posterior's regression ``A = P_bp P_pp^-1``, the mean of
the bias given the plane, so the model the taxels see moves as little as the posterior
allows. Two limits keep this a refinement, not another model:

* no mirrored point moves further than the model surface's own std (``surface_std_m``).
  Where the touch did not observe the plane (jaws closing across it leave its offset
  free), the posterior is wide and the nearest plane the camera accepts may lie tens of
  millimetres away, on the silhouette's edge, as wrong as the fused one; within the noise,
  conditioning only settles what the free-space test cannot resolve. The search runs over
  the steps so bounded (:func:`motion_basis`, :func:`nearest_feasible`);
* the plane stays within the ellipse that holds ``1 - alpha`` of the marginal's mass
  (Mahalanobis norm ``sqrt(-2 ln alpha)``, the chi-square quantile with two degrees of
  freedom): a plane further off contradicts the posterior rather than refining it.

The conditioned model replaces the stage when it passes every test; the stage keeps its
status, its covariances and its points. :func:`.problem.estimate_result` tries it only
when Stage 0 cannot be held (:func:`.hypotheses.holdable`): where the taxels accept vision
alone, the hypotheses that stay near it decide.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from pipeline.estimation.consistency import ConsistencySettings, assess, model_free_space_count
from pipeline.estimation.geometry import mirror, plane_normal, plane_tangent
from pipeline.estimation.iekf import FusionProblem
from pipeline.estimation.problem import stage_estimate
from pipeline.types import Consistency, DepthObservation, Hypothesis, StageEstimate

#: The name recorded in ``StageEstimate.hypothesis``.
CONDITIONED = "conditioned on free space"
#: Indices of the bias ``(b_theta, b_x, b_y, b_z)`` and the plane ``(m_r, m_theta)`` in ``g``.
BIAS, PLANE = [0, 1, 2, 3], [4, 5]
#: Directions searched around the fused plane (evenly spaced in the unit disc of
#: :func:`motion_basis`).
DIRECTIONS = 36
#: Bisection steps along each direction (resolution 1/256 of the allowed motion).
BISECTION_STEPS = 8


def motion_basis(points_m: np.ndarray, g: np.ndarray, bound_m: float) -> np.ndarray:
    """``(2, 2)`` matrix ``B`` such that a plane step ``d = B e`` with ``|e_1| + |e_2| <= 1``
    moves no mirrored point ``f_m(p)`` further than ``bound_m`` (to first order), and steps
    along ``e_1`` or ``e_2`` alone move some point by exactly that.

    A step ``(dm_r, dm_theta)`` moves ``f_m(p)`` by ``2 (dm_r - dm_theta s) n - 2 dm_theta h n'``
    with ``s = n'.p`` (along the plane) and ``h = n.p - m_r`` (off it). Written with the
    offset at the middle ``c`` of the points' span along the plane, ``r' = dm_r - dm_theta c``,
    that is at most ``2 (|r'| + L |dm_theta|)`` for the lever ``L``, the largest
    ``sqrt((s - c)^2 + h^2)``. So ``e = (2 r', 2 L dm_theta) / bound_m`` makes the allowed
    steps about a unit disc: between the diamond ``|e_1| + |e_2| <= 1`` and the unit square.
    A step along the plane's angle alone, about the origin of the frame, would sweep the
    object through the lever of its distance from that origin.
    """
    n = plane_normal(g[5])
    along = plane_tangent(g[5])
    s = points_m @ along
    h = points_m @ n - g[4]
    centre = 0.5 * (float(np.min(s)) + float(np.max(s)))
    lever = float(np.max(np.hypot(s - centre, h)))
    return 0.5 * bound_m * np.array([[1.0, centre / lever], [0.0, 1.0 / lever]])


def nearest_feasible(
    covariance: np.ndarray,
    feasible: Callable[[np.ndarray], bool],
    basis: np.ndarray,
    allowed: Callable[[np.ndarray], bool] = lambda step: True,
    directions: int = DIRECTIONS,
    bisection_steps: int = BISECTION_STEPS,
) -> np.ndarray | None:
    """Of the allowed steps ``d = basis (rho u)``, ``0 < rho <= 1``, along ``directions``
    evenly spaced unit ``u``, the feasible one of smallest Mahalanobis norm
    ``d^T C^-1 d``, or None when none is.

    Along each direction, bisection first finds how far the steps stay allowed (``allowed``
    is assumed to hold from the origin out to some ``rho`` and not beyond), then, when the
    furthest allowed step is feasible, where feasibility starts (assumed to hold from there
    out: a plane moved further from the fused one in the same direction pulls the mirror
    image further back into the silhouette). The Mahalanobis norm grows along a direction,
    so that start is the direction's best step. The feasible set need not be convex across
    directions.

    Args:
        covariance: ``(2, 2)`` symmetric positive-definite ``C``.
        feasible: whether a step passes (``feasible(0)`` is assumed false).
        basis: ``(2, 2)`` map from the unit disc to the steps searched.
        allowed: which steps may be taken at all (all by default).
    """
    precision = np.linalg.inv(covariance)
    best = None
    for angle in np.linspace(0.0, 2.0 * np.pi, directions, endpoint=False):
        ray = basis @ np.array([np.cos(angle), np.sin(angle)])
        furthest = 1.0
        if not allowed(ray):
            furthest, _ = _bisect(allowed, ray, False, 0.0, 1.0, bisection_steps)
        if furthest == 0.0 or not feasible(furthest * ray):
            continue
        _, start = _bisect(feasible, ray, True, 0.0, furthest, bisection_steps)
        step = start * ray
        norm = float(step @ precision @ step)
        if best is None or norm < best[0]:
            best = (norm, step)
    return None if best is None else best[1]


def _bisect(
    predicate: Callable[[np.ndarray], bool],
    ray: np.ndarray,
    at_high: bool,
    low: float,
    high: float,
    steps: int,
) -> tuple[float, float]:
    """``[low, high]`` narrowed ``steps`` times around where ``predicate(rho ray)`` changes,
    given that it is ``at_high`` at ``high`` and not at ``low``."""
    for _ in range(steps):
        middle = 0.5 * (low + high)
        if predicate(middle * ray) == at_high:
            high = middle
        else:
            low = middle
    return low, high


def conditioned_state(g: np.ndarray, covariance: np.ndarray, plane_step: np.ndarray) -> np.ndarray:
    """``g`` with its plane moved by ``plane_step`` and its bias by the posterior's
    regression on the plane, ``A plane_step`` with ``A = P_bp P_pp^-1`` (``covariance`` the
    ``(6, 6)`` posterior of ``g``)."""
    regression = covariance[np.ix_(BIAS, PLANE)] @ np.linalg.inv(covariance[np.ix_(PLANE, PLANE)])
    moved = np.array(g, dtype=float)
    moved[PLANE] += plane_step
    moved[BIAS] += regression @ plane_step
    return moved


def condition(
    fusion: FusionProblem,
    stage: StageEstimate,
    g: np.ndarray,
    verdict: Consistency,
    view: DepthObservation,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> StageEstimate | None:
    """``stage`` (final state ``g``, diagnosis ``verdict``) conditioned on free space, with
    its own status, time and covariances and the conditioned model's diagnosis; None when
    the free-space test alone does not flag it, or when no plane searched gives a model that
    passes every test."""
    if verdict.passes_free_space or not verdict.nis <= verdict.nis_threshold:
        return None
    covariance = np.asarray(stage.covariance, dtype=float)
    points = stage.points
    limit = verdict.free_space_limit
    mirrored = mirror(points, g)

    def with_plane(plane_step: np.ndarray) -> np.ndarray:
        state = np.array(g, dtype=float)
        state[PLANE] += plane_step
        return state

    def passes(plane_step: np.ndarray) -> bool:
        tolerance_m = settings.free_space_tolerance_m
        return model_free_space_count(points, with_plane(plane_step), view, tolerance_m) <= limit

    def within_noise(plane_step: np.ndarray) -> bool:
        motion = np.linalg.norm(mirror(points, with_plane(plane_step)) - mirrored, axis=1)
        return bool(np.max(motion, initial=0.0) <= settings.surface_std_m)

    plane_covariance = covariance[np.ix_(PLANE, PLANE)]
    basis = motion_basis(points, g, settings.surface_std_m)
    plane_step = nearest_feasible(plane_covariance, passes, basis, within_noise)
    # The chi-square quantile with two degrees of freedom: ``-2 ln alpha``.
    largest = -2.0 * np.log(settings.alpha)
    if plane_step is None or plane_step @ np.linalg.solve(plane_covariance, plane_step) > largest:
        return None
    conditioned = conditioned_state(g, covariance, plane_step)
    grasp_g = [conditioned + (np.asarray(g_k) - g) for g_k in stage.grasp_g]
    checked = assess(
        points, conditioned, grasp_g, fusion.pivot_m, fusion.grasps, view, settings, tree
    )
    if not checked.consistent:
        return None
    estimate = stage_estimate(
        stage.stage,
        conditioned,
        covariance,
        points,
        fusion.pivot_m,
        stage.iterations,
        stage.status,
        stage.seconds,
        stage.active_points,
        (),
        grasp_g,
        stage.filter_covariance,
    )
    hypothesis = Hypothesis(name=CONDITIONED, replaced=verdict.reason)
    return replace(estimate, trace=stage.trace, consistency=checked, hypothesis=hypothesis)
