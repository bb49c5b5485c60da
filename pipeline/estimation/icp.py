"""Maximum-likelihood (ICP-style) baseline the paper argues against (paper sec. 5.1).

Each taxel is matched to its single nearest point among the front images ``f_b(p)`` and
the back images ``f_mb(p)`` (Euclidean, in frame R; no match beyond
``max_match_distance_m``). With the matches fixed, the same MAP objective as the IEKF is
minimised with :func:`scipy.optimize.least_squares`:

    sum_i |R_i^-1/2 (T_i - f(p_n(i)))|^2 + |P_g^-1/2 (g - g-)|^2 [+ sum_n |p_n - p-_n|^2 / s_n^2]

over ``g`` (Stage 1) or ``g`` and the matched points (Stage 2); then the taxels are matched
again, until the matches stop changing. Grasps are processed in order; between grasps the
covariance of ``g`` is the Gauss-Newton one ``(J^T J)^-1`` plus ``Q``, and the points keep
their prior variance (cross-covariances are not carried: this is a baseline).
Statuses follow :mod:`.iekf`: ``no_correspondence`` when no taxel has a match.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.optimize
from scipy.spatial import cKDTree

from pipeline.estimation.geometry import apply_side, invert_side, side_jacobian, side_linear_part
from pipeline.estimation.iekf import FusionProblem, GraspContacts, StageOutcome, worst_status


@dataclass(frozen=True)
class IcpSettings:
    """Iteration control of the baseline (units as named)."""

    max_iterations: int = 20
    max_match_distance_m: float = 0.02
    divergence_sigmas: float = 10.0


def _matches(tree, points, g, pivot_m, taxels_m, limit_m):
    """Nearest front/back point of each taxel: (point index, back flag, matched mask)."""
    distance_front, nearest_front = tree.query(invert_side(taxels_m, g, pivot_m, False))
    distance_back, nearest_back = tree.query(invert_side(taxels_m, g, pivot_m, True))
    back = distance_back < distance_front
    nearest = np.where(back, nearest_back, nearest_front)
    distance = np.minimum(distance_front, distance_back)
    return nearest, back, distance <= limit_m


def _solve(
    g_prior,
    covariance,
    points_prior,
    variance,
    pivot_m,
    taxels_m,
    whiten,
    n,
    back,
    g_start,
    move_points,
):
    # Eleven parameters: a numeric kernel given the prior, the matches and the weights as arrays.
    """Least-squares MAP solve with fixed matches; returns g, moved points, cov of g."""
    unique, slot = np.unique(n, return_inverse=True) if move_points else (n[:0], None)
    dim = len(g_prior)  # six parameters, or seven with a leaning plane
    prior_whiten = np.linalg.inv(np.linalg.cholesky(covariance))
    point_scale = 1.0 / np.sqrt(variance[unique])

    def split(z):
        return z[:dim], z[dim:].reshape(-1, 3)

    def current_points(moved):
        return moved[slot] if move_points else points_prior[n]

    def residuals(z):
        g, moved = split(z)
        matched = current_points(moved)
        predicted = np.empty_like(matched)
        for side in (False, True):
            predicted[back == side] = apply_side(matched[back == side], g, pivot_m, side)
        taxel_part = np.einsum("mij,mj->mi", whiten, taxels_m - predicted).ravel()
        prior_part = prior_whiten @ (g - g_prior)
        point_part = ((moved - points_prior[unique]) * point_scale[:, None]).ravel()
        return np.concatenate([taxel_part, prior_part, point_part])

    def jacobian(z):
        g, moved = split(z)
        matched = current_points(moved)
        rows = 3 * len(n)
        result = np.zeros((rows + dim + 3 * len(unique), len(z)))
        taxel_jac = np.empty((len(n), 3, dim))
        linear = np.empty((len(n), 3, 3))
        for side in (False, True):
            taxel_jac[back == side] = side_jacobian(matched[back == side], g, pivot_m, side)
            linear[back == side] = side_linear_part(g, side)
        result[:rows, :dim] = -np.einsum("mij,mjk->mik", whiten, taxel_jac).reshape(rows, dim)
        if move_points:
            blocks = -np.einsum("mij,mjk->mik", whiten, linear)
            for m in range(len(n)):
                column = dim + 3 * slot[m]
                result[3 * m : 3 * m + 3, column : column + 3] = blocks[m]
        result[rows : rows + dim, :dim] = prior_whiten
        diagonal = np.arange(3 * len(unique))
        result[rows + dim + diagonal, dim + diagonal] = np.repeat(point_scale, 3)
        return result

    z0 = np.concatenate([g_start, points_prior[unique].ravel()])
    solution = scipy.optimize.least_squares(residuals, z0, jac=jacobian, method="lm")
    information = solution.jac.T @ solution.jac
    g, moved = split(solution.x)
    g_covariance = np.linalg.inv(information)[:dim, :dim]
    return g, unique, moved, g_covariance


def _grasp(
    problem,
    contacts: GraspContacts,
    settings,
    g_prior,
    covariance,
    points_prior,
    g_start,
    move_points,
    halfwidth,
):
    # Nine parameters: the kernel's state and settings for one grasp, as arrays and numbers.
    whiten = np.linalg.inv(np.linalg.cholesky(contacts.noise))
    g, points, g_cov = np.array(g_start, float), points_prior, covariance
    previous, status, iterations = None, "max_iterations", 0
    for iterations in range(1, settings.max_iterations + 1):
        tree = cKDTree(points)
        nearest, back, matched = _matches(
            tree, points, g, problem.pivot_m, contacts.positions_m, settings.max_match_distance_m
        )
        if not matched.any():
            return g_prior, covariance, points_prior, "no_correspondence", iterations, 0
        key = (tuple(nearest[matched]), tuple(back[matched]), tuple(np.flatnonzero(matched)))
        if key == previous:
            status = "converged"
            break
        previous = key
        g, unique, moved, g_cov = _solve(
            g_prior,
            covariance,
            points_prior,
            problem.point_variance_m2,
            problem.pivot_m,
            contacts.positions_m[matched],
            whiten[matched],
            nearest[matched],
            back[matched],
            g,
            move_points,
        )
        if move_points:
            points = points_prior.copy()
            points[unique] = moved
        sane = np.all(np.abs(g - problem.g_init) <= halfwidth)
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(moved)) and sane):
            return g_prior, covariance, points_prior, "diverged", iterations, 0
    return g, g_cov, points, status, iterations, int(np.count_nonzero(matched))


def icp_fuse(
    problem: FusionProblem, settings: IcpSettings, last_stage: Literal[1, 2] = 2
) -> tuple[StageOutcome, ...]:
    """Stages 1 (and 2) of the ICP baseline, with the outcome layout of :func:`.iekf.fuse`.

    ``active_points`` counts the taxels with a match (one point each).
    """
    halfwidth = settings.divergence_sigmas * np.sqrt(
        np.diag(problem.covariance_init + max(len(problem.grasps) - 1, 0) * problem.regrasp_noise)
    )
    outcomes: list[StageOutcome] = []
    for stage in range(1, last_stage + 1):
        started = time.perf_counter()
        g, covariance, points = (
            np.array(problem.g_init, float),
            problem.covariance_init,
            problem.points_m,
        )
        statuses, iterations, active, grasp_g, grasp_cov = [], 0, 0, [], []
        for k, contacts in enumerate(problem.grasps):
            if k > 0:
                covariance = covariance + problem.regrasp_noise
            g_start = g if stage == 1 else outcomes[0].grasp_g[k]
            g, covariance, points, status, used, active = _grasp(
                problem,
                contacts,
                settings,
                g,
                covariance,
                points,
                g_start,
                stage == 2,
                halfwidth,
            )
            statuses.append(status)
            iterations += used
            grasp_g.append(g.copy())
            grasp_cov.append(covariance)
        outcomes.append(
            StageOutcome(
                g=g,
                covariance=covariance,
                points=points,
                status=worst_status(statuses),
                iterations=iterations,
                active_points=active,
                seconds=time.perf_counter() - started,
                grasp_g=tuple(grasp_g),
                grasp_covariance=tuple(grasp_cov),
            )
        )
    return tuple(outcomes)
