"""Alternative hypotheses when fusion contradicts the evidence: the held plane, the motion
test on the bias, and that a consistent fusion is never replaced."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from estimation_scenes import cylinder_scene, fusion_problem
from test_estimation_consistency import flat_view, stage

from pipeline.estimation.consistency import ConsistencySettings
from pipeline.estimation.hypotheses import (
    HYPOTHESES,
    Candidate,
    held_problem,
    holdable,
    motion_limit,
    moved_free_space,
    shortened_covariance,
    unheld_covariance,
)
from pipeline.estimation.iekf import IekfSettings, fuse
from pipeline.estimation.map_params import consistency_settings
from pipeline.estimation.map_params import fusion_problem as map_fusion_problem
from pipeline.estimation.problem import estimate_result
from pipeline.io.formats import stage_to_json
from pipeline.metrics import diameter_error
from pipeline.synthetic import make_case
from pipeline.types import Consistency, StageEstimate
from plugins.estimators.iekf import IekfEstimator


def test_held_plane_fusion_keeps_the_plane_and_still_corrects_the_bias():
    scene = cylinder_scene(3000)
    g_init = np.zeros(6)  # the right plane, the bias not yet known
    problem = fusion_problem(scene, g_init)
    held = held_problem(problem, HYPOTHESES["held-plane"])
    assert np.all(held.covariance_init[4:, :] == 0.0) and np.all(held.covariance_init[:, 4:] == 0)
    assert np.array_equal(held.covariance_init[:4, :4], problem.covariance_init[:4, :4])
    stage_one, stage_two = fuse(held, IekfSettings())
    for outcome in (stage_one, stage_two):
        assert outcome.status in ("converged", "max_iterations")
        assert np.array_equal(outcome.g[4:], g_init[4:])
    # The touch moved the object 3 mm along the grasp; the held-plane fusion finds it.
    assert stage_two.g[1] == pytest.approx(scene.g_true[1], abs=0.001)


def test_holding_the_angle_leaves_the_plane_distance_from_the_pivot_uncertain():
    problem, _ = iekf_fusion(cylinder_case())
    prior = problem.covariance_init
    held = held_problem(problem, HYPOTHESES["held-angle"]).covariance_init
    assert np.all(held[5, :] == 0.0) and np.all(held[:, 5] == 0.0)
    # m_r = offset + n'(m_theta) . pivot: with the angle known only the offset's variance
    # is left, the Schur complement (the pivot's lever arm makes the prior's much larger).
    assert held[4, 4] == pytest.approx(prior[4, 4] - prior[4, 5] ** 2 / prior[5, 5])
    assert 0.0 < held[4, 4] < prior[4, 4]


@pytest.mark.parametrize("name", sorted(HYPOTHESES))
def test_putting_the_held_uncertainty_back_on_an_unmeasured_prior_gives_the_prior(name):
    # Without a measurement the re-fusion's posterior is the prior conditioned on the held
    # components; the law of total covariance must then give back the prior itself.
    rng = np.random.default_rng(3)
    root = rng.normal(size=(6, 6))
    prior = root @ root.T + 0.1 * np.eye(6)
    problem = dataclasses.replace(
        fusion_problem(cylinder_scene(200), np.zeros(6)), covariance_init=prior
    )
    conditioned = held_problem(problem, HYPOTHESES[name]).covariance_init
    restored = unheld_covariance(conditioned, prior, HYPOTHESES[name])
    np.testing.assert_allclose(restored, prior, rtol=1e-10, atol=1e-12)
    # A measured free component keeps its smaller variance on top of what the held add.
    measured = conditioned.copy()
    measured[1, 1] *= 0.5
    assert unheld_covariance(measured, prior, HYPOTHESES[name])[1, 1] < prior[1, 1]


def test_moved_free_space_counts_only_what_the_bias_change_moves():
    view = flat_view(1.0)  # a wall at x = 1 m, seen along +x
    rng = np.random.default_rng(0)
    points = np.column_stack(
        [np.full(500, 1.0), rng.uniform(-0.2, 0.2, 500), rng.uniform(-0.1, 0.1, 500)]
    )
    # A plane far behind the wall: the mirror images lie beyond it, never in free space.
    g = np.array([0.0, 0.0, 0.0, 0.0, 1.5, 0.0])
    tolerance = ConsistencySettings().free_space_tolerance_m
    pivot = points.mean(axis=0)
    assert moved_free_space(points, g, g, pivot, view, tolerance) == 0
    towards_camera = g + np.array([0.0, -0.02, 0.0, 0.0, 0.0, 0.0])
    assert moved_free_space(points, towards_camera, g, pivot, view, tolerance) == 500
    away = g + np.array([0.0, 0.02, 0.0, 0.0, 0.0, 0.0])
    assert moved_free_space(points, away, g, pivot, view, tolerance) == 0


def test_motion_limit_is_the_false_alarm_count_quantile():
    # 10,000 points at alpha 0.001: 10 expected, std 3.16, z = 3.09 -> 19.8 -> 20.
    assert motion_limit(10_000, 0.001) == 20
    assert motion_limit(0, 0.001) == 0


def wrong_outcomes(fusion, settings):
    """What a fusion that went astray returns: the right fused states with the plane moved
    25 mm and turned 30 deg, so the completed back sweeps through seen free space."""
    astray = np.array([0.0, 0.0, 0.0, 0.0, 0.025, math.radians(30.0)])
    return tuple(
        dataclasses.replace(
            outcome,
            g=outcome.g + astray,
            grasp_g=tuple(g_k + astray for g_k in outcome.grasp_g),
        )
        for outcome in fuse(fusion, settings)
    )


def cylinder_case():
    """A parallel-jaw grasp of the synthetic cylinder, plane right, object moved 3 mm."""
    return make_case(
        np.random.default_rng(1), bias_magnitude_m=0.003, bias_direction_rad=math.radians(30.0)
    )


def iekf_fusion(case):
    """The ``iekf`` estimator's kernel problem for ``case`` and its iteration settings."""
    estimator = IekfEstimator()
    p = estimator.params
    window = (p.window_along_normal_m, p.window_across_normal_m)
    fusion = map_fusion_problem(case.problem, p, "iekf", window, p.facing_filter)
    return fusion, estimator.settings()


def test_an_inconsistent_fusion_is_replaced_by_a_consistent_closer_held_plane_model():
    case = cylinder_case()
    fusion, settings = iekf_fusion(case)
    checks = consistency_settings(IekfEstimator().params)
    outcomes = wrong_outcomes(fusion, settings)
    started = time.perf_counter()
    plain = estimate_result(fusion, outcomes, started, case.problem.view, checks)
    assert plain.stage(0).consistency.consistent
    assert plain.final.status == "inconsistent" and plain.selected_stage == 0

    def refuse(problem):
        return fuse(problem, settings)

    revised = estimate_result(fusion, outcomes, started, case.problem.view, checks, refuse)
    final = revised.final
    assert final.hypothesis is not None and final.hypothesis.name.split(",")[0] in HYPOTHESES
    assert final.hypothesis.replaced == plain.final.consistency.reason
    assert final.consistency.consistent and final.status in ("converged", "max_iterations")
    assert revised.selected_stage == 2
    assert final.plane.theta_rad == fusion.g_init[5]
    diameter = case.cylinder.diameter_m
    fused_error = abs(diameter_error(plain.final.completed, diameter))
    held_error = abs(diameter_error(final.completed, diameter))
    assert held_error < 0.004 < fused_error
    assert stage_to_json(final)["hypothesis"]["name"] == final.hypothesis.name
    assert stage_to_json(revised.stage(0))["hypothesis"] is None


def test_a_consistent_fusion_is_never_replaced():
    case = cylinder_case()
    fusion, settings = iekf_fusion(case)
    calls = []

    def refuse(problem):
        calls.append(problem)
        return fuse(problem, settings)

    outcomes = fuse(fusion, settings)
    result = estimate_result(
        fusion,
        outcomes,
        time.perf_counter(),
        case.problem.view,
        consistency_settings(IekfEstimator().params),
        refuse,
    )
    assert result.final.consistency.consistent and result.selected_stage == 2
    assert calls == []
    assert all(stage.hypothesis is None for stage in result.stages)
    assert np.array_equal(result.final.points, outcomes[-1].points)


def test_no_hypothesis_when_stage_zero_is_inconsistent_too():
    """Far-off initial plane: Stage 0 contradicts the image, so there is nothing to hold."""
    case = make_case(np.random.default_rng(1), theta_error_rad=math.radians(80.0), r_error_m=0.04)
    result = IekfEstimator().estimate(case.problem)
    assert not result.stage(0).consistency.consistent
    assert all(stage.hypothesis is None for stage in result.stages)


def verdict(nis: float, violations: int, limit: int = 100) -> Consistency:
    return Consistency(
        checks=("taxels", "free_space"),
        taxel_rms_m=0.001,
        nis=nis,
        nis_threshold=5.0,
        free_space_violations=violations,
        free_space_limit=limit,
        consistent=nis <= 5.0 and violations <= limit,
    )


def candidate(nis: float, violations: int, still: bool = True) -> Candidate:
    g = np.zeros(6)
    return Candidate("held-angle", 1.0, g, (g,), np.zeros((1, 3)), verdict(nis, violations), still)


def test_a_hypothesis_is_no_worse_than_stage_zero_only_on_every_test():
    consistent, grazing = verdict(1.0, 10), verdict(1.0, 150)
    assert candidate(2.0, 90).no_worse_than(consistent)
    assert not candidate(2.0, 120).no_worse_than(consistent)  # over the limit
    assert candidate(2.0, 140).no_worse_than(grazing)  # over it, but less than Stage 0
    assert not candidate(2.0, 160).no_worse_than(grazing)
    assert not candidate(6.0, 10).no_worse_than(consistent)  # the taxels contradict it
    assert not candidate(2.0, 10, still=False).no_worse_than(consistent)  # the bias moved it


def test_stage_zero_is_held_only_when_the_taxels_accept_it_and_it_is_less_contradicted():
    def stage_with(consistency: Consistency) -> StageEstimate:
        return dataclasses.replace(stage(0, 0.1), status="initial", consistency=consistency)

    fused = stage_with(verdict(0.1, 900))
    assert holdable(stage_with(verdict(1.0, 10)), fused)
    assert holdable(stage_with(verdict(1.0, 150)), fused)  # only the image, and less
    assert not holdable(stage_with(verdict(6.0, 10)), fused)  # the taxels reject it
    assert not holdable(stage_with(verdict(1.0, 1000)), fused)  # more contradicted


@pytest.mark.parametrize("step", [0.0, 0.25, 0.5, 1.0])
def test_a_shortened_step_has_the_covariance_of_its_error_by_monte_carlo(step):
    """Linear-Gaussian oracle: draw the prior error and the measurement noise, update by the
    Kalman gain, take the state ``step`` of the way from the prior mean to the posterior
    one; the sample covariance of its error matches :func:`shortened_covariance`."""
    rng = np.random.default_rng(4)
    root = rng.normal(size=(3, 3))
    prior = root @ root.T + np.eye(3)
    H = rng.normal(size=(2, 3))
    R = np.diag([0.3, 0.5])
    gain = prior @ H.T @ np.linalg.inv(H @ prior @ H.T + R)
    posterior = (np.eye(3) - gain @ H) @ prior
    samples = 200_000
    prior_error = rng.multivariate_normal(np.zeros(3), prior, size=samples)
    noise = rng.multivariate_normal(np.zeros(2), R, size=samples)
    # e_post = e_prior - K (H e_prior + v): the posterior mean's error
    posterior_error = prior_error - (prior_error @ H.T + noise) @ gain.T
    error = (1.0 - step) * prior_error + step * posterior_error
    expected = shortened_covariance(prior, (posterior + posterior.T) / 2.0, step)
    np.testing.assert_allclose(np.cov(error.T), expected, atol=0.03 * np.abs(prior).max())
