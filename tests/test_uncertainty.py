"""The next-grasp information score and the stop rule's uncertainties against independent
computations: finite differences, the information form of Bayes' rule on the dense state,
and a brute-force posterior on a grid over the plane averaged over simulated measurements."""

from dataclasses import replace

import numpy as np
import pytest

from pipeline.estimation.correspondences import PointIndex, exclusive_sides, find_correspondences
from pipeline.estimation.geometry import apply_bias, apply_mirror_bias, invert_bias
from pipeline.estimation.measurement import freeze, predict
from pipeline.estimation.problem import grasp_contacts
from pipeline.estimation.structured import block_diagonal
from pipeline.estimation.uncertainty import (
    expected_gain_m2,
    hidden_shape_std_m,
    hidden_side_gram,
    hidden_side_std_m,
    model_gram,
    plane_offset_std_m,
    predicted_measurement,
)
from pipeline.types import Contacts

WINDOW = (0.003, 0.0017)
NOISE = (0.001, 0.003)


def _box_front(rng):
    """A 40 x 30 mm front face at x = 0.5 m seen by the camera, with a little depth noise."""
    y, z = np.meshgrid(np.linspace(-0.02, 0.02, 9), np.linspace(0.03, 0.06, 7))
    points = np.column_stack([np.full(y.size, 0.5), y.ravel(), z.ravel()])
    return points + rng.normal(0.0, 2e-4, points.shape)


def _problem(rng):
    """Points, state (plane 20 mm behind the face), pivot, and four taxels: two on the
    front face and two on the mirrored back face, one of each pair near a corner."""
    points = _box_front(rng)
    pivot = points.mean(axis=0)
    g = np.array([0.01, 0.0005, -0.0005, 0.0, 0.52, 0.0])
    back = apply_mirror_bias(points, g, pivot)
    front = points + np.array([0.0005, -0.0005, 0.0])  # the bias, nearly
    picks = [30, 10]
    positions = np.vstack([front[picks], back[picks]])
    normals = np.array([[1.0, 0, 0], [1.0, 0, 0], [-1.0, 0, 0], [-1.0, 0, 0]])
    contacts = Contacts(positions, normals, ["left", "left", "right", "right"], [0, 1, 0, 1])
    # The paper's noise across the normal too, so that the oracles below test the score's
    # algebra on a measurement that informs every direction.
    taxels = grasp_contacts(contacts, WINDOW, NOISE)
    return points, g, pivot, replace(taxels, reported_noise=None, pad_errors_m=None)


def _frozen(points, g, pivot, taxels, covariance):
    found = find_correspondences(
        PointIndex(points),
        points,
        g,
        pivot,
        taxels.positions_m,
        taxels.window,
        covariance,
        alternative=False,
        need_pairs=True,
        taxel_normals=taxels.normals,
        facing_g=g,
    )
    return freeze(exclusive_sides(found), taxels.positions_m, taxels.noise)


def _numeric_jacobian(function, x, step=1e-7):
    base = function(x)
    columns = []
    for k in range(len(x)):
        shifted = x.copy()
        shifted[k] += step
        columns.append((function(shifted) - base) / step)
    return np.column_stack(columns)


def _subset_gain(points, g, pivot, taxels, subset, covariance, gram, point_std_m=0.002):
    """:func:`expected_gain_m2` of the taxels ``subset`` alone."""
    contacts = type(taxels)(
        taxels.positions_m[subset],
        taxels.pads[subset],
        taxels.window[subset],
        taxels.noise[subset],
        taxels.normals[subset],
    )
    variance = np.full(len(points), point_std_m**2)
    H, N = predicted_measurement(
        PointIndex(points), points, g, pivot, contacts, covariance, variance
    )
    return expected_gain_m2(covariance, H, N, gram)


def test_gain_matches_bayes_on_the_dense_state():
    """The score (covariance form, points marginalised into S, trace over the hidden side
    by the Gram matrix) equals the information-form posterior of the full dense state with
    finite-difference Jacobians of the measurement and of the mirror images."""
    rng = np.random.default_rng(3)
    points, g, pivot, taxels = _problem(rng)
    covariance = np.diag([0.03, 0.004, 0.004, 0.002, 0.01, 0.2]) ** 2
    point_std = 0.002
    index = PointIndex(points)
    variance = np.full(len(points), point_std**2)
    jacobian, nuisance = predicted_measurement(
        index, points, g, pivot, taxels, covariance, variance
    )
    assert len(jacobian) > 0
    gram = hidden_side_gram(points, g, pivot)
    score = expected_gain_m2(covariance, jacobian, nuisance, gram)

    measurement = _frozen(points, g, pivot, taxels, covariance)
    n = len(points)
    state = np.concatenate([g, points.ravel()])

    def h(x):
        return predict(measurement, x[:6], x[6:].reshape(n, 3), pivot)

    H = _numeric_jacobian(h, state)
    prior = np.zeros((6 + 3 * n, 6 + 3 * n))
    prior[:6, :6] = covariance
    prior[6:, 6:] = point_std**2 * np.eye(3 * n)
    R = block_diagonal(measurement.noise)
    posterior = np.linalg.inv(np.linalg.inv(prior) + H.T @ np.linalg.solve(R, H))
    reduction = covariance - posterior[:6, :6]

    def hidden(x):
        return apply_mirror_bias(points, x, pivot).ravel()

    J = _numeric_jacobian(hidden, g).reshape(n, 3, 6)
    oracle = np.mean([np.trace(J[k] @ reduction @ J[k].T) for k in range(n)])
    assert score > 0
    assert score == pytest.approx(oracle, rel=1e-4)
    # The hidden-side std before the grasp, from the same finite-difference Jacobians.
    rms = np.sqrt(np.mean([np.trace(J[k] @ covariance @ J[k].T) for k in range(n)]))
    assert hidden_side_std_m(covariance, gram) == pytest.approx(rms, rel=1e-5)


def test_gain_matches_brute_force_expected_posterior_over_the_plane():
    """Only the plane is uncertain (bias and points known): the expected posterior of
    ``(m_r, m_theta)`` by Bayes' rule on a grid, averaged over measurements simulated with
    the nonlinear measurement function (frozen weights), gives the score's reduction of
    the hidden side's mean squared std within the Monte Carlo and linearisation error."""
    rng = np.random.default_rng(5)
    points, g, pivot, taxels = _problem(rng)
    stds = np.array([1e-6, 1e-6, 1e-6, 1e-6, 0.004, 0.06])
    covariance = np.diag(stds**2)
    index = PointIndex(points)
    variance = np.full(len(points), 1e-14)
    jacobian, nuisance = predicted_measurement(
        index, points, g, pivot, taxels, covariance, variance
    )
    gram = hidden_side_gram(points, g, pivot)
    score = expected_gain_m2(covariance, jacobian, nuisance, gram)

    measurement = _frozen(points, g, pivot, taxels, covariance)
    R = block_diagonal(measurement.noise)
    R_inv = np.linalg.inv(R)
    r_axis = g[4] + np.linspace(-5, 5, 101) * stds[4]
    t_axis = g[5] + np.linspace(-5, 5, 101) * stds[5]
    grid = np.array([(r, t) for r in r_axis for t in t_axis])
    log_prior = -0.5 * np.sum(((grid - g[4:]) / stds[4:]) ** 2, axis=1)

    def h(plane):
        return predict(measurement, np.concatenate([g[:4], plane]), points, pivot)

    predictions = np.array([h(plane) for plane in grid])
    noise_factor = np.linalg.cholesky(R)
    posterior_covariances = []
    for _ in range(400):
        truth = g[4:] + stds[4:] * rng.standard_normal(2)
        y = h(truth) + noise_factor @ rng.standard_normal(len(R))
        residual = predictions - y
        log_post = log_prior - 0.5 * np.einsum("ki,ij,kj->k", residual, R_inv, residual)
        weights = np.exp(log_post - log_post.max())
        weights /= weights.sum()
        mean = weights @ grid
        centred = grid - mean
        posterior_covariances.append((weights[:, None] * centred).T @ centred)
    expected = np.mean(posterior_covariances, axis=0)
    reduction = covariance.copy()
    reduction[4:, 4:] -= expected
    reduction[:4, :4] = 0.0
    brute_force = float(np.trace(reduction @ gram))
    assert brute_force > 0
    assert score == pytest.approx(brute_force, rel=0.05)


def test_no_contact_no_gain_and_more_taxels_more_gain():
    rng = np.random.default_rng(7)
    points, g, pivot, taxels = _problem(rng)
    covariance = np.diag([0.03, 0.004, 0.004, 0.002, 0.01, 0.2]) ** 2
    gram = hidden_side_gram(points, g, pivot)
    index = PointIndex(points)
    variance = np.full(len(points), 0.002**2)
    assert expected_gain_m2(covariance, np.zeros((0, 6)), np.zeros((0, 0)), gram) == 0.0
    far = Contacts(np.array([[0.9, 0.4, 0.05]]), np.array([[1.0, 0, 0]]), ["left"], [0])
    jacobian, _ = predicted_measurement(
        index, points, g, pivot, grasp_contacts(far, WINDOW, NOISE), covariance, variance
    )
    assert jacobian.shape == (0, 6)

    def score(subset):
        return _subset_gain(points, g, pivot, taxels, subset, covariance, gram)

    front_only, both_sides = score([0, 1]), score([0, 1, 2, 3])
    assert 0.0 < front_only < both_sides


def test_model_gram_is_both_sides_spread_where_the_object_stands():
    rng = np.random.default_rng(5)
    points, g, pivot, taxels = _problem(rng)
    gram = model_gram(points, g, pivot)
    covariance = np.diag([0.03, 0.004, 0.004, 0.002, 0.003, 0.05]) ** 2
    # Finite differences of the visible side moved by the bias and of its mirror image.
    n = len(points)
    front = _numeric_jacobian(lambda x: apply_bias(points, x, pivot).ravel(), g.copy())
    back = _numeric_jacobian(lambda x: apply_mirror_bias(points, x, pivot).ravel(), g.copy())
    jacobians = np.concatenate([front.reshape(n, 3, 6), back.reshape(n, 3, 6)])
    expected = np.mean([np.trace(J @ covariance @ J.T) for J in jacobians])
    assert np.trace(covariance @ gram) == pytest.approx(expected, rel=1e-4)
    # The visible side does not depend on the plane: a plane-only covariance moves the
    # mirror image alone, half the points.
    plane_only = np.diag([0.0, 0.0, 0.0, 0.0, 0.003, 0.05]) ** 2
    hidden = np.trace(plane_only @ hidden_side_gram(points, g, pivot))
    assert np.trace(plane_only @ gram) == pytest.approx(hidden / 2, rel=1e-9)

    # Taxels on the front face alone pin the object's place, which the model gram counts;
    # both faces teach more.
    prior = np.diag([0.03, 0.004, 0.004, 0.002, 0.01, 0.2]) ** 2

    def gain(subset):
        return _subset_gain(points, g, pivot, taxels, subset, prior, gram)

    assert 0.0 < gain([0, 1]) < gain([0, 1, 2, 3])


def test_plane_offset_std_is_the_distance_from_the_pivot():
    """Turning the plane about a point on it does not change its distance from that point:
    a covariance along that rotation has no offset std there; the finite-difference
    gradient of the distance gives the rest."""
    pivot = np.array([0.5, 0.2, 0.05])
    g = np.array([0.0, 0.0, 0.0, 0.0, 0.55, 0.3])

    def distance(x):
        normal = np.array([np.cos(x[5]), np.sin(x[5])])
        return np.array([x[4] - normal @ pivot[:2]])

    gradient = _numeric_jacobian(distance, g)[0]
    covariance = np.diag([1e-3, 2e-5, 2e-5, 4e-6, 1e-4, 0.04])
    expected = np.sqrt(gradient @ covariance @ gradient)
    assert plane_offset_std_m(covariance, g, pivot) == pytest.approx(expected, rel=1e-5)
    along_rotation = np.zeros(6)
    along_rotation[5] = 1.0
    along_rotation[4] = -gradient[5]
    pure = 0.01 * np.outer(along_rotation, along_rotation)
    assert plane_offset_std_m(pure, g, pivot) == pytest.approx(0.0, abs=1e-7)


def test_hidden_shape_std_is_the_hidden_side_in_the_object_s_own_frame():
    """The hidden side moved back by the bias it stands at (finite differences over the
    whole state, full covariance with bias-plane correlations) has the shape std; a
    re-grasp's noise on the bias leaves it as it is and grows the hidden side's std."""
    rng = np.random.default_rng(5)
    points, g, pivot, _ = _problem(rng)
    root = rng.normal(size=(6, 6)) * np.array([0.03, 0.004, 0.004, 0.002, 0.01, 0.2])
    covariance = root.T @ root
    n = len(points)

    def shape(x):
        return invert_bias(apply_mirror_bias(points, x, pivot), x, pivot).ravel()

    J = _numeric_jacobian(shape, g).reshape(n, 3, 6)
    rms = np.sqrt(np.mean([np.trace(J[k] @ covariance @ J[k].T) for k in range(n)]))
    gram = hidden_side_gram(points, g, pivot)
    assert hidden_shape_std_m(covariance, gram) == pytest.approx(rms, rel=1e-5)
    regrasp = np.diag([0.02, 0.01, 0.01, 0.001, 0.0, 0.0]) ** 2
    grown = covariance + regrasp
    assert hidden_shape_std_m(grown, gram) == pytest.approx(hidden_shape_std_m(covariance, gram))
    assert hidden_side_std_m(grown, gram) > hidden_side_std_m(covariance, gram)
