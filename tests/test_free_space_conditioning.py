"""A fused stage that only the free-space test flags is conditioned on free space: the
search for the nearest passing plane against closed forms, the bias's regression against a
direct minimisation, and the whole path on the synthetic cylinder."""

from __future__ import annotations

import dataclasses
import math
import time
from functools import partial

import numpy as np
import pytest
from scipy.optimize import minimize

from pipeline.estimation.free_space_conditioning import (
    CONDITIONED,
    conditioned_state,
    motion_basis,
    nearest_feasible,
)
from pipeline.estimation.geometry import mirror, plane_normal
from pipeline.estimation.iekf import fuse
from pipeline.estimation.map_params import consistency_settings
from pipeline.estimation.map_params import fusion_problem as map_fusion_problem
from pipeline.estimation.problem import estimate_result
from pipeline.metrics import diameter_error
from pipeline.synthetic import make_case
from plugins.estimators.iekf import IekfEstimator

COVARIANCE = np.array([[4e-6, 3e-5], [3e-5, 0.04]])
#: Steps out to 4 posterior stds, searched along whitened directions.
WHITENED = 4.0 * np.linalg.cholesky(COVARIANCE)


def mahalanobis(step: np.ndarray) -> float:
    return math.sqrt(step @ np.linalg.solve(COVARIANCE, step))


@pytest.mark.parametrize("normal_deg", [0.0, 70.0, 160.0, 250.0])
def test_the_nearest_step_into_a_half_plane_is_the_closed_form_one(normal_deg):
    """Feasible: ``a . d >= b``. The nearest point in the metric of ``C`` is
    ``C a b / (a^T C a)``, at Mahalanobis distance ``b / sqrt(a^T C a)``."""
    scale = np.sqrt(np.diag(COVARIANCE))
    a = np.array([math.cos(math.radians(normal_deg)), math.sin(math.radians(normal_deg))]) / scale
    b = 1.7 * math.sqrt(a @ COVARIANCE @ a)
    step = nearest_feasible(COVARIANCE, lambda d: a @ d >= b, WHITENED)
    assert step is not None and a @ step >= b
    # Directions 10 deg apart leave at most 1 / cos(5 deg) - 1 of the distance, and the
    # bisection a 256th of the 4 stds searched; a point on the boundary that much further
    # than the nearest lies at most sqrt(2 b excess) from it.
    excess = 1.7 * (1.0 / math.cos(math.radians(5.0)) - 1.0) + 4.0 / 256
    assert 1.7 <= mahalanobis(step) <= 1.7 + excess
    expected = COVARIANCE @ a * b / (a @ COVARIANCE @ a)
    gap = np.linalg.solve(np.linalg.cholesky(COVARIANCE), step - expected)
    assert np.linalg.norm(gap) <= math.sqrt(2.0 * 1.7 * excess)


def test_no_step_when_nothing_searched_passes():
    calls = []

    def feasible(d):
        calls.append(d)
        return mahalanobis(d) >= 5.0

    assert nearest_feasible(COVARIANCE, feasible, WHITENED) is None
    assert calls and max(mahalanobis(d) for d in calls) <= 4.0 + 1e-9


def test_only_allowed_steps_are_taken():
    """Allowed: within 1 std; feasible: the offset 0.5 std up or more. Out to 4 stds the
    nearest feasible step would be the same; the allowed ones stop short of others."""
    sigma = math.sqrt(COVARIANCE[0, 0])

    def allowed(d):
        return mahalanobis(d) <= 1.0

    step = nearest_feasible(COVARIANCE, lambda d: d[0] >= 0.5 * sigma, WHITENED, allowed)
    assert step is not None and mahalanobis(step) <= 1.0 and step[0] >= 0.5 * sigma
    assert nearest_feasible(COVARIANCE, lambda d: d[0] >= 1.5 * sigma, WHITENED, allowed) is None


def test_the_nearest_of_two_separate_passing_regions_is_found():
    """Not convex: a far region straight along the first direction searched, a near one
    opposite it."""
    sigma = np.sqrt(np.diag(COVARIANCE))
    step = nearest_feasible(
        COVARIANCE, lambda d: d[0] >= 3.0 * sigma[0] or d[0] <= -1.2 * sigma[0], WHITENED
    )
    assert step is not None and step[0] < 0.0
    assert mahalanobis(step) < 1.3


@pytest.mark.parametrize("theta_deg", [0.0, 35.0, 200.0])
def test_the_motion_basis_bounds_how_far_the_mirror_image_moves(theta_deg):
    """Exact mirror images: steps on the diamond ``|e_1| + |e_2| = 1`` move no point further
    than the bound, and the steps along each axis move some point by the bound, so the
    search covers what the bound allows. That holds to first order: the plane's distance
    from the frame's origin, 0.5 m here, adds ``m_r dm_theta^2 / 2`` to the offset's step,
    about 7 % of the bound; the search checks every step exactly."""
    rng = np.random.default_rng(7)
    theta = math.radians(theta_deg)
    centre = np.array([0.5, -0.2, 0.05])
    points = centre + rng.uniform(-0.04, 0.04, size=(500, 3))
    g = np.array([0.0, 0.0, 0.0, 0.0, centre @ plane_normal(theta) + 0.003, theta])
    bound = 0.002
    basis = motion_basis(points, g, bound)
    base = mirror(points, g)

    def motion(e):
        moved = g.copy()
        moved[4:] += basis @ e
        return float(np.max(np.linalg.norm(mirror(points, moved) - base, axis=1)))

    for angle in np.linspace(0.0, 2.0 * np.pi, 40, endpoint=False):
        e = np.array([math.cos(angle), math.sin(angle)])
        assert motion(e / np.abs(e).sum()) <= bound * 1.1
    for e in ([1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]):
        assert motion(np.array(e)) == pytest.approx(bound, rel=0.1)


def test_the_bias_follows_the_plane_by_the_posterior_conditional_mean():
    """With the plane fixed at ``g_p + d``, the bias minimising the posterior's Mahalanobis
    distance (found by a general minimiser) is what :func:`conditioned_state` gives."""
    rng = np.random.default_rng(4)
    root = rng.normal(size=(6, 6)) * np.array([0.05, 0.01, 0.01, 0.002, 0.003, 0.1])
    covariance = root @ root.T + 1e-8 * np.eye(6)
    g = rng.normal(size=6) * 0.01
    step = np.array([0.004, -0.05])
    precision = np.linalg.inv(covariance)

    def distance(bias):
        x = np.concatenate([bias, g[4:] + step]) - g
        return x @ precision @ x

    best = minimize(distance, g[:4], method="BFGS", options={"gtol": 1e-12}).x
    moved = conditioned_state(g, covariance, step)
    np.testing.assert_allclose(moved[4:], g[4:] + step)
    np.testing.assert_allclose(moved[:4], best, atol=1e-6)


def side_grasp(moved_m: float = 0.016):
    """The synthetic cylinder grasped from the side (tactile angle 90 deg): the jaws close
    across the view, so they do not see where along it the back lies. The object moved
    ``moved_m`` before the grasp: 16 mm puts the taxels off Stage 0, so vision alone is no
    option and the fused stage is what conditioning can refine."""
    case = make_case(
        np.random.default_rng(1),
        tactile_angle_rad=math.radians(90.0),
        bias_magnitude_m=moved_m,
        bias_direction_rad=math.radians(30.0),
    )
    estimator = IekfEstimator()
    p = estimator.params
    window = (p.window_along_normal_m, p.window_across_normal_m)
    fusion = map_fusion_problem(case.problem, p, "iekf", window, p.facing_filter)
    return case, fusion, estimator.settings(), consistency_settings(p)


def drifted(outcomes, covariance, offset_m, along_jaws_m=0.0):
    """The fused stages with the plane moved ``offset_m`` toward the camera, the object
    ``along_jaws_m`` along the jaws, and ``covariance`` as their posterior: a drift along a
    direction the taxels left open."""
    shift = np.array([0.0, 0.0, along_jaws_m, 0.0, offset_m, 0.0])
    return tuple(
        dataclasses.replace(
            outcome,
            g=outcome.g + shift,
            grasp_g=tuple(g_k + shift for g_k in outcome.grasp_g),
            covariance=covariance,
        )
        for outcome in outcomes
    )


def offset_posterior(outcomes, std_m):
    """The last stage's posterior with the plane's offset known to ``std_m``, uncorrelated
    with the rest."""
    covariance = np.array(outcomes[-1].covariance, dtype=float)
    covariance[4, :] = covariance[:, 4] = 0.0
    covariance[4, 4] = std_m**2
    return covariance


def estimates(case, fusion, settings, checks, astray):
    """``astray`` diagnosed as is, and with the estimator's alternatives (conditioning
    among them)."""
    started = time.perf_counter()
    view = case.problem.view
    plain = estimate_result(fusion, astray, started, view, checks)
    refuse = partial(fuse, settings=settings)
    return plain, estimate_result(fusion, astray, started, view, checks, refuse)


@pytest.mark.slow
def test_a_drift_the_camera_rules_out_is_conditioned_away():
    """The offset known to 4 mm and 12 mm off: the camera accepts the model once the plane
    is moved back by less than a millimetre."""
    case, fusion, settings, checks = side_grasp()
    outcomes = fuse(fusion, settings)
    covariance = offset_posterior(outcomes, 0.004)
    astray = drifted(outcomes, covariance, 0.012)
    plain, result = estimates(case, fusion, settings, checks, astray)
    flagged = plain.final.consistency
    assert not flagged.passes_free_space and flagged.nis <= flagged.nis_threshold
    assert plain.final.status == "inconsistent"
    final = result.final
    assert final.hypothesis is not None and final.hypothesis.name == CONDITIONED
    assert final.hypothesis.replaced == flagged.reason
    assert final.consistency.consistent and final.status == astray[-1].status
    assert result.selected_stage == 2
    step_m = astray[-1].g[4] - final.plane.offset_m
    # A mirrored point moves by twice the offset's step, at most one cloud point's std.
    assert 0.0 < step_m <= checks.surface_std_m / 2
    diameter = case.cylinder.diameter_m
    assert abs(diameter_error(final.completed, diameter)) < abs(
        diameter_error(plain.final.completed, diameter)
    )
    np.testing.assert_array_equal(final.points, astray[-1].points)
    np.testing.assert_array_equal(final.covariance, covariance)


@pytest.mark.slow
def test_a_marginal_drift_is_conditioned_away_however_wide_the_posterior():
    """The offset's posterior its prior (32 mm std): the plane needed moves back by less
    than a millimetre, far inside the search's first ring at that scale."""
    case, fusion, settings, checks = side_grasp()
    outcomes = fuse(fusion, settings)
    prior_std_m = math.sqrt(fusion.covariance_init[4, 4])
    astray = drifted(outcomes, offset_posterior(outcomes, prior_std_m), 0.012)
    plain, result = estimates(case, fusion, settings, checks, astray)
    assert not plain.final.consistency.passes_free_space
    final = result.final
    assert final.hypothesis is not None and final.hypothesis.name == CONDITIONED
    assert final.consistency.consistent
    assert 0.0 < astray[-1].g[4] - final.plane.offset_m <= checks.surface_std_m / 2


@pytest.mark.slow
def test_a_drift_beyond_the_model_noise_is_not_conditioned_away():
    """The offset known to 8 mm and 20 mm off: the nearest plane the camera accepts lies
    about 8 mm back, within the posterior but further than the model's own noise; conditioning
    would build another model, not settle a marginal test."""
    case, fusion, settings, checks = side_grasp()
    outcomes = fuse(fusion, settings)
    astray = drifted(outcomes, offset_posterior(outcomes, 0.008), 0.02)
    plain, result = estimates(case, fusion, settings, checks, astray)
    flagged = plain.final.consistency
    assert not flagged.passes_free_space and flagged.nis <= flagged.nis_threshold
    assert all(s.hypothesis is None or s.hypothesis.name != CONDITIONED for s in result.stages)


@pytest.mark.slow
def test_a_stage_whose_taxels_fail_is_not_conditioned():
    """The first drift with the object placed 10 mm along the jaws: the taxels contradict
    the model too, so conditioning on free space alone cannot explain the evidence."""
    case, fusion, settings, checks = side_grasp()
    outcomes = fuse(fusion, settings)
    astray = drifted(outcomes, offset_posterior(outcomes, 0.004), 0.012, along_jaws_m=0.01)
    plain, result = estimates(case, fusion, settings, checks, astray)
    flagged = plain.final.consistency
    assert not flagged.passes_free_space and not flagged.nis <= flagged.nis_threshold
    assert all(s.hypothesis is None or s.hypothesis.name != CONDITIONED for s in result.stages)


@pytest.mark.slow
def test_a_stage_zero_the_taxels_accept_is_held_not_the_fusion_conditioned():
    """The object moved 3 mm: the taxels accept Stage 0, so the flagged fusion goes to the
    hypotheses that stay near it (docs/method.md §9), not to conditioning."""
    case, fusion, settings, checks = side_grasp(0.003)
    outcomes = fuse(fusion, settings)
    astray = drifted(outcomes, offset_posterior(outcomes, 0.004), 0.013)
    plain, result = estimates(case, fusion, settings, checks, astray)
    assert plain.stage(0).consistency.consistent
    flagged = plain.final.consistency
    assert not flagged.passes_free_space and flagged.nis <= flagged.nis_threshold
    assert all(s.hypothesis is None or s.hypothesis.name != CONDITIONED for s in result.stages)
