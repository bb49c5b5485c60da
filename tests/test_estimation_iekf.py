"""The structured IEKF against independent oracles: finite differences, filterpy's EKF,
scipy's least squares, the dense textbook reference, and a known synthetic truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.optimize
from estimation_scenes import (
    cylinder_scene,
    frozen_measurement,
    fusion_problem,
    one_step_and_filterpy,
    structured_and_dense,
)

from pipeline.estimation.covariances import shared_pad_noise
from pipeline.estimation.geometry import apply_bias, apply_mirror_bias
from pipeline.estimation.iekf import IekfSettings, fuse
from pipeline.estimation.measurement import linearise, predict
from pipeline.estimation.structured import StructuredCovariance, block_diagonal

G_INIT = np.array([0.0, 0.0, 0.0, 0.0, 0.008, 0.08])


@pytest.fixture(scope="module")
def scene():
    return cylinder_scene(250, seed=3)


def _state(g, points):
    return np.concatenate([g, points.ravel()])


def _completed(g, points, pivot):
    return np.vstack([apply_bias(points, g, pivot), apply_mirror_bias(points, g, pivot)])


def test_stacked_jacobian_matches_central_differences(scene):
    problem = fusion_problem(scene, G_INIT)
    measurement = frozen_measurement(problem, G_INIT, scene.points_m)
    g = G_INIT + np.array([0.01, 0.001, -0.002, 0.0005, 0.001, -0.02])
    points = scene.points_m + 1e-3
    lin = linearise(measurement, g, points, problem.pivot_m, with_points=True)
    n = len(points)
    analytic = np.hstack([lin.bias_plane_jacobian, lin.point_jacobian.dense(n)])
    used = np.unique(measurement.pair_point)
    columns = np.concatenate([np.arange(6), 6 + (3 * used[:, None] + np.arange(3)).ravel()])
    x = _state(g, points)
    step = 1e-7
    for column in columns:
        dx = np.zeros_like(x)
        dx[column] = step
        plus, minus = x + dx, x - dx
        numeric = (
            predict(measurement, plus[:6], plus[6:].reshape(-1, 3), problem.pivot_m)
            - predict(measurement, minus[:6], minus[6:].reshape(-1, 3), problem.pivot_m)
        ) / (2 * step)
        np.testing.assert_allclose(analytic[:, column], numeric, atol=1e-6)
    unused = np.setdiff1d(np.arange(6, 6 + 3 * n), columns)
    assert not np.any(analytic[:, unused])


def test_point_jacobian_products_match_the_dense_matrix(scene):
    problem = fusion_problem(scene, G_INIT)
    measurement = frozen_measurement(problem, G_INIT, scene.points_m)
    jacobian = linearise(measurement, G_INIT, scene.points_m, problem.pivot_m, True).point_jacobian
    local = jacobian.points()
    variance = np.random.default_rng(5).uniform(1e-6, 4e-6, len(local))
    dense = jacobian.dense(len(scene.points_m))[:, (3 * local[:, None] + np.arange(3)).ravel()]
    np.testing.assert_allclose(
        jacobian.weighted_gram(local, variance),
        dense @ np.diag(np.repeat(variance, 3)) @ dense.T,
        rtol=1e-12,
        atol=1e-18,
    )
    vector = np.random.default_rng(6).normal(size=len(dense))
    np.testing.assert_allclose(
        jacobian.transpose_times(local, vector).ravel(), dense.T @ vector, rtol=1e-12, atol=1e-15
    )


def test_one_iteration_equals_filterpy_ekf_update(scene):
    problem = fusion_problem(scene, G_INIT)
    ours, ours_covariance, ekf_state, ekf_covariance = one_step_and_filterpy(
        problem, G_INIT, scene.points_m
    )
    np.testing.assert_allclose(ours, ekf_state, atol=1e-10)
    np.testing.assert_allclose(ours_covariance, ekf_covariance, atol=1e-12)


def test_converged_iterate_is_the_map_least_squares_minimiser():
    scene = cylinder_scene(100, seed=5)
    problem = fusion_problem(scene, G_INIT)
    points_prior = scene.points_m
    measurement = frozen_measurement(problem, G_INIT, points_prior)
    covariance = StructuredCovariance(problem.covariance_init, problem.point_variance_m2)
    g, points = G_INIT.copy(), points_prior.copy()
    for _ in range(50):
        lin = linearise(measurement, g, points, problem.pivot_m, with_points=True)
        innovation = (
            measurement.observation()
            - lin.prediction
            + lin.bias_plane_jacobian @ (g - G_INIT)
            + lin.point_jacobian.times_displacement(points, points_prior)
        )
        delta_g, moved, delta_p = covariance.gain(lin, measurement.noise).step(innovation)
        g_next, points_next = G_INIT + delta_g, points_prior.copy()
        points_next[moved] += delta_p
        step = max(np.abs(g_next - g).max(), np.abs(points_next - points).max())
        g, points = g_next, points_next
        if step < 1e-13:
            break

    used = np.unique(measurement.pair_point)
    prior_whiten = np.linalg.inv(np.linalg.cholesky(problem.covariance_init))
    noise_whiten = np.linalg.inv(np.linalg.cholesky(block_diagonal(measurement.noise)))
    sigma = np.sqrt(problem.point_variance_m2[used])

    def residuals(z):
        trial = points_prior.copy()
        trial[used] = z[6:].reshape(-1, 3)
        taxel = measurement.observation() - predict(measurement, z[:6], trial, problem.pivot_m)
        return np.concatenate(
            [
                noise_whiten @ taxel,
                prior_whiten @ (z[:6] - G_INIT),
                ((trial[used] - points_prior[used]) / sigma[:, None]).ravel(),
            ]
        )

    z0 = np.concatenate([G_INIT, points_prior[used].ravel()])
    # Levenberg-Marquardt (MINPACK): same optimum and tolerances, ~8x fewer evaluations of
    # the 3-point Jacobian than the default trust-region reflective method here.
    solution = scipy.optimize.least_squares(
        residuals, z0, jac="3-point", method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15
    )
    np.testing.assert_allclose(g, solution.x[:6], atol=1e-8)
    np.testing.assert_allclose(points[used], solution.x[6:].reshape(-1, 3), atol=1e-8)
    untouched = np.setdiff1d(np.arange(len(points)), used)
    np.testing.assert_array_equal(points[untouched], points_prior[untouched])


@pytest.mark.parametrize(("grasps", "reported"), [(1, None), (2, None), (2, (1.0, 0.001))])
def test_structured_and_dense_agree(scene, grasps, reported):
    across, pad = (None, None) if reported is None else reported
    problem = fusion_problem(
        scene, G_INIT, grasps=grasps, reported_across_m=across, reported_pad_m=pad
    )
    structured, dense = structured_and_dense(problem)
    np.testing.assert_allclose(
        _completed(structured[1].g, structured[1].points, problem.pivot_m),
        _completed(dense[1].g, dense[1].points, problem.pivot_m),
        atol=1e-6,
    )


@pytest.mark.parametrize("schedule", ["standard", "alternative", "hybrid"])
def test_fusion_recovers_bias_and_plane_errors(scene, schedule):
    problem = fusion_problem(scene, G_INIT)
    stage_1, stage_2 = fuse(problem, IekfSettings(schedule=schedule))
    before = scene.surface_distance(_completed(G_INIT, scene.points_m, problem.pivot_m)).mean()
    after_1 = scene.surface_distance(_completed(stage_1.g, stage_1.points, problem.pivot_m))
    after_2 = scene.surface_distance(_completed(stage_2.g, stage_2.points, problem.pivot_m))
    assert before > 0.004
    assert after_1.mean() < 0.5 * before
    assert after_2.mean() < 0.5 * before
    assert abs(stage_2.g[4] - scene.g_true[4]) < 0.002  # m_r within 2 mm of the truth
    assert stage_2.active_points > 0
    assert np.all(np.linalg.eigvalsh(stage_2.covariance) > 0)
    assert np.all(np.diag(stage_2.covariance) < np.diag(problem.covariance_init))


def test_taxels_far_from_every_point_give_no_correspondence(scene):
    problem = fusion_problem(scene, G_INIT)
    far = dataclasses.replace(problem.grasps[0], positions_m=problem.grasps[0].positions_m + 1.0)
    problem = dataclasses.replace(problem, grasps=(far,))
    for outcome in fuse(problem, IekfSettings(schedule="standard")):
        assert outcome.status == "no_correspondence"
        np.testing.assert_array_equal(outcome.g, G_INIT)
        np.testing.assert_array_equal(outcome.covariance, problem.covariance_init)
    # eq. 13 always finds points (by design), so the hybrid schedule chases the far taxels
    # until the state leaves the sane region.
    assert {o.status for o in fuse(problem, IekfSettings(schedule="hybrid"))} == {"diverged"}


def test_leaving_the_sane_region_is_reported_as_diverged(scene):
    problem = fusion_problem(scene, G_INIT)
    outcomes = fuse(problem, IekfSettings(divergence_sigmas=1e-3))
    assert [o.status for o in outcomes] == ["diverged", "diverged"]
    np.testing.assert_array_equal(outcomes[1].g, G_INIT)


def test_the_reported_covariance_counts_the_taxels_along_their_normals_only(scene):
    """The pads press along x. Their frozen-weight residuals across the normal make the
    filter's own covariance claim the cylinder's y position nearly as well as its x; the
    reported one, counting each taxel along its normal only, keeps y at the prior's std and
    still learns x; with the paper's noise it is the filter's own. Oracle: the information
    form with the Jacobian of the iterate the last gain was computed at."""
    settings = IekfSettings(schedule="standard", refine_gates=False)
    honest = fusion_problem(scene, G_INIT, reported_across_m=1.0)
    stage_1 = fuse(honest, settings, last_stage=1)[0]
    own = stage_1.grasp_covariance[-1]
    prior = np.sqrt(np.diag(honest.covariance_init))
    assert np.sqrt(own[2, 2]) < 0.2 * prior[2]  # the filter's claim on y
    assert np.sqrt(stage_1.covariance[2, 2]) > 0.95 * prior[2]
    assert np.sqrt(stage_1.covariance[1, 1]) < 0.2 * prior[1]
    paper = fuse(fusion_problem(scene, G_INIT), settings, last_stage=1)[0]
    np.testing.assert_allclose(paper.covariance, paper.grasp_covariance[-1], atol=1e-15)
    np.testing.assert_allclose(stage_1.covariance, _information_form(scene, honest, stage_1))


def test_an_error_a_pad_shares_bounds_what_its_taxels_tell_together(scene):
    """With 1 mm shared by each pad's taxels the two pads cannot locate the cylinder along x
    better than 1 mm / sqrt(2), however many taxels touch (alone they claim far less); the
    information form with the full noise matrix is the oracle."""
    settings = IekfSettings(schedule="standard", refine_gates=False)
    alone = fuse(fusion_problem(scene, G_INIT, reported_across_m=1.0), settings, last_stage=1)
    shared = fusion_problem(scene, G_INIT, reported_across_m=1.0, reported_pad_m=0.001)
    stage_1 = fuse(shared, settings, last_stage=1)[0]
    assert np.sqrt(alone[0].covariance[1, 1]) < 0.0004
    assert 0.001 / np.sqrt(2.0) < np.sqrt(stage_1.covariance[1, 1]) < 0.001
    np.testing.assert_allclose(stage_1.covariance, _information_form(scene, shared, stage_1))


def _information_form(scene, problem, outcome):
    """``(P0^-1 + H^T R^-1 H)^-1`` at the iterate of the last gain, ``R`` the reported
    noise: block-diagonal per taxel plus, by hand, the error each pad's taxels share."""
    g = outcome.trace[-2].g
    measurement = frozen_measurement(problem, g, problem.points_m)
    lin = linearise(measurement, g, problem.points_m, problem.pivot_m, with_points=False)
    H = lin.bias_plane_jacobian
    contacts = problem.grasps[0]
    noise = block_diagonal(contacts.reported_noise[measurement.taxel])
    if contacts.pad_errors_m is not None:
        errors = contacts.pad_errors_m[measurement.taxel]
        pads = contacts.pads[measurement.taxel]
        for i in range(len(errors)):
            for j in range(len(errors)):
                if pads[i] == pads[j]:
                    noise[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] += np.outer(errors[i], errors[j])
    information = np.linalg.inv(problem.covariance_init) + H.T @ np.linalg.solve(noise, H)
    return np.linalg.inv(information)


def test_shared_pad_noise_by_hand():
    u = np.array([[0.001, 0.0, 0.0], [0.002, 0.0, 0.0], [0.0, 0.003, 0.0]])
    matrix = shared_pad_noise(u, np.array(["left", "left", "right"]))
    expected = np.zeros((9, 9))
    expected[0, 0], expected[0, 3], expected[3, 0], expected[3, 3] = 1e-6, 2e-6, 2e-6, 4e-6
    expected[7, 7] = 9e-6
    np.testing.assert_allclose(matrix, expected, atol=1e-18)
