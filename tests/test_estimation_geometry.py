"""Geometry, covariance and correspondence kernels against independent oracles."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull
from scipy.stats import multivariate_normal

from pipeline.estimation.alternative_centres import (
    _mahalanobis_nearest,
    alternative_centres,
    vector_median,
)
from pipeline.estimation.correspondences import (
    GATE_CHI2_3DOF_95,
    PointIndex,
    find_correspondences,
    side_covariances,
)
from pipeline.estimation.covariances import normal_ellipsoids
from pipeline.estimation.geometry import (
    apply_side,
    completed_model,
    image_step_bound,
    invert_side,
    rebase_bias_translation,
    side_jacobian,
    side_linear_part,
)
from pipeline.types import Bias, SymmetryPlane

RNG = np.random.default_rng(7)
G = np.array([0.3, 0.01, -0.02, 0.005, 0.013, 0.7])
PIVOT = np.array([0.1, -0.05, 0.2])


@pytest.mark.parametrize("back", [False, True])
def test_side_jacobian_matches_central_differences(back):
    points = RNG.normal(0.0, 0.1, (5, 3))
    analytic = side_jacobian(points, G, PIVOT, back)
    step = 1e-6
    for k in range(6):
        dg = np.zeros(6)
        dg[k] = step
        numeric = (
            apply_side(points, G + dg, PIVOT, back) - apply_side(points, G - dg, PIVOT, back)
        ) / (2 * step)
        np.testing.assert_allclose(analytic[:, :, k], numeric, atol=1e-8)


@pytest.mark.parametrize("back", [False, True])
def test_point_jacobian_matches_central_differences(back):
    point = RNG.normal(0.0, 0.1, (1, 3))
    numeric = np.empty((3, 3))
    for k in range(3):
        dp = np.zeros((1, 3))
        dp[0, k] = 1e-6
        numeric[:, k] = (
            apply_side(point + dp, G, PIVOT, back) - apply_side(point - dp, G, PIVOT, back)
        )[0] / 2e-6
    np.testing.assert_allclose(side_linear_part(G, back), numeric, atol=1e-8)


@pytest.mark.parametrize("back", [False, True])
def test_inverse_and_contract_types_agree(back):
    points = RNG.normal(0.0, 0.1, (10, 3))
    np.testing.assert_allclose(
        invert_side(apply_side(points, G, PIVOT, back), G, PIVOT, back), points
    )
    bias = Bias(yaw_rad=G[0], translation_m=G[1:4], pivot_m=PIVOT)
    plane = SymmetryPlane(theta_rad=G[5], offset_m=G[4])
    expected = bias.apply(plane.mirror(points)) if back else bias.apply(points)
    np.testing.assert_allclose(apply_side(points, G, PIVOT, back), expected, atol=1e-15)


def test_rebased_bias_is_the_same_rigid_motion():
    points = RNG.normal(0.0, 0.1, (10, 3))
    old = Bias(yaw_rad=0.4, translation_m=[0.01, 0.02, 0.03], pivot_m=[0.0, 0.0, 0.0])
    translation = rebase_bias_translation(0.4, old.translation_m, old.pivot_m, PIVOT)
    new = Bias(yaw_rad=0.4, translation_m=translation, pivot_m=PIVOT)
    np.testing.assert_allclose(new.apply(points), old.apply(points), atol=1e-15)


def test_normal_ellipsoid_eigenstructure():
    normal = np.array([[0.0, 0.6, 0.8]])
    ellipsoid = normal_ellipsoids(normal, 0.001, 0.003)[0]
    np.testing.assert_allclose(ellipsoid @ normal[0], 1e-6 * normal[0], atol=1e-15)
    tangent = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(ellipsoid @ tangent, 9e-6 * tangent, atol=1e-15)


def test_image_step_bound_is_the_largest_motion_over_the_hull_and_its_margin():
    points = RNG.normal(0.0, 0.04, (2000, 3))
    vertices = points[ConvexHull(points).vertices]
    g_new = G + np.array([0.02, 0.001, -0.003, 0.0005, 0.004, -0.05])

    def largest_motion(cloud):
        return max(
            np.max(
                np.linalg.norm(
                    apply_side(cloud, g_new, PIVOT, b) - apply_side(cloud, G, PIVOT, b), axis=1
                )
            )
            for b in (False, True)
        )

    assert image_step_bound(vertices, G, g_new, PIVOT) == pytest.approx(largest_motion(points))
    margin = 0.01
    offsets = RNG.normal(size=points.shape)
    shifted = points + margin * offsets / np.linalg.norm(offsets, axis=1, keepdims=True)
    bound = image_step_bound(vertices, G, g_new, PIVOT, margin)
    assert largest_motion(shifted) <= bound < largest_motion(points) + 2 * margin * 0.1


def test_completed_model_is_the_front_then_the_mirrored_cloud():
    points = np.random.default_rng(3).normal(0.0, 0.1, (50, 3))
    expected = np.vstack([apply_side(points, G, PIVOT, back) for back in (False, True)])
    np.testing.assert_allclose(completed_model(points, G, PIVOT), expected, rtol=0, atol=1e-15)


def test_vector_median_picks_the_central_member():
    cluster = np.array([[[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [2.5, 0, 0], [40.0, 0, 0]]])
    np.testing.assert_allclose(vector_median(cluster), [[2.0, 0, 0]])


def test_mahalanobis_nearest_matches_brute_force():
    points = RNG.normal(0.0, 0.05, (3000, 3))
    centres = RNG.normal(0.0, 0.05, (20, 3))
    normals = RNG.normal(size=(20, 3))
    covariances = normal_ellipsoids(normals, 0.02, 0.002)
    index = PointIndex(points)
    chosen, d2 = _mahalanobis_nearest(index, points, centres, covariances, 5, 0.0)
    inverse = np.linalg.inv(covariances)
    offsets = points[None, :, :] - centres[:, None, :]
    all_d2 = np.einsum("tni,tij,tnj->tn", offsets, inverse, offsets)
    np.testing.assert_array_equal(chosen, np.argsort(all_d2, axis=1)[:, :5])
    np.testing.assert_allclose(d2, np.sort(all_d2, axis=1)[:, :5])


def test_alternative_centres_match_brute_force():
    """Eq. 13: the vector median of the five Mahalanobis-closest images over both sides."""
    angle = RNG.uniform(np.pi / 2, 3 * np.pi / 2, 4000)
    points = np.column_stack(
        [0.04 * np.cos(angle), 0.04 * np.sin(angle), RNG.uniform(0, 0.1, 4000)]
    )
    taxels = np.array([[-0.041, 0.002, 0.05], [0.0415, -0.003, 0.04], [0.043, 0.001, 0.06]])
    window = normal_ellipsoids(np.tile([1.0, 0.0, 0.0], (3, 1)), 0.006, 0.0015)
    g = np.array([0.02, 0.001, -0.002, 0.0, 0.004, 0.05])
    pivot = points.mean(axis=0)
    state_covariance = np.diag([0.02, 0.003, 0.003, 0.001, 0.008, 0.1]) ** 2
    covariances = tuple(
        side_covariances(taxels, window, g, pivot, state_covariance, back) for back in (False, True)
    )
    got = alternative_centres(PointIndex(points), points, g, pivot, taxels, covariances, 0.0)
    images = np.concatenate([apply_side(points, g, pivot, back) for back in (False, True)])
    for i, taxel in enumerate(taxels):
        d2 = np.concatenate(
            [
                np.einsum(
                    "ni,ij,nj->n", side - taxel, np.linalg.inv(covariances[b][i]), side - taxel
                )
                for b, side in enumerate(np.split(images, 2))
            ]
        )
        closest = images[np.argsort(d2)[:5]]
        summed = np.linalg.norm(closest[:, None] - closest[None], axis=-1).sum(axis=1)
        np.testing.assert_allclose(got[i], closest[np.argmin(summed)], atol=1e-12)


def _gated_densities(images, centre, covariance):
    """Dense oracle of eq. 9: scipy's Gaussian density of every image, zero outside the gate."""
    offsets = images - centre
    d2 = np.einsum("ni,ij,nj->n", offsets, np.linalg.inv(covariance), offsets)
    densities = multivariate_normal(centre, covariance).pdf(images)
    densities[d2 >= GATE_CHI2_3DOF_95] = 0.0
    return densities


def test_standard_weights_match_dense_gaussian_densities():
    points = RNG.uniform(-0.03, 0.03, (2000, 3))
    taxels = RNG.uniform(-0.02, 0.02, (6, 3))
    window = normal_ellipsoids(RNG.normal(size=(6, 3)), 0.004, 0.0015)
    state_covariance = np.diag([0.01, 0.002, 0.002, 0.002, 0.003, 0.02]) ** 2
    index = PointIndex(points)
    found = find_correspondences(
        index, points, G, PIVOT, taxels, window, state_covariance, alternative=False
    )
    for side in found.sides():
        _assert_dense_weights(side, points, G, taxels, window, state_covariance)


def _assert_dense_weights(side, points, g, taxels, window, state_covariance):
    """Every listed weight and mass of ``side`` is the dense oracle's."""
    covariance = side_covariances(taxels, window, g, PIVOT, state_covariance, side.back)
    images = apply_side(points, g, PIVOT, side.back)
    for i in range(len(taxels)):
        expected = _gated_densities(images, taxels[i], covariance[i])
        got = np.zeros(len(points))
        got[side.point[side.taxel == i]] = side.weight[side.taxel == i]
        np.testing.assert_allclose(got, expected, rtol=1e-9)
        assert side.mass[i] == pytest.approx(expected.sum(), rel=1e-9)


def test_kept_gate_candidates_give_the_dense_weights_as_the_state_moves():
    """The listed gates' candidates kept between calls (GateCandidates): the second call
    keeps them, after small steps of the state they cover the new gates and are reused,
    after a large one they do not and are searched again; either way every weight is the
    dense oracle's."""
    # A generator of its own: the draws of the tests after it stay as they were.
    rng = np.random.default_rng(11)
    points = rng.uniform(-0.03, 0.03, (2000, 3))
    taxels = rng.uniform(-0.02, 0.02, (6, 3))
    window = normal_ellipsoids(rng.normal(size=(6, 3)), 0.004, 0.0015)
    state_covariance = np.diag([0.01, 0.002, 0.002, 0.002, 0.003, 0.02]) ** 2
    index = PointIndex(points)
    step = np.array([0.001, 0.0002, -0.0001, 0.0001, 0.0002, 0.002])
    reused = []
    for g in (G, G + step, G + 2 * step, G + 3 * step, G + 23 * step):
        kept = dict(index.candidates)
        found = find_correspondences(
            index, points, g, PIVOT, taxels, window, state_covariance, alternative=False
        )
        for side in found.sides():
            if (side.back, False) in kept:
                reused.append(index.candidates[(side.back, False)] is kept[(side.back, False)])
            _assert_dense_weights(side, points, g, taxels, window, state_covariance)
    # Both sides reuse their candidates after the two small steps, neither after the jump.
    assert reused == [True, True, True, True, False, False]


@pytest.mark.parametrize("need_pairs", [True, False])
def test_wide_gate_sums_match_dense_gaussian_densities(need_pairs, monkeypatch):
    # The exact whole-cloud sums are what is checked here: with the voxel aggregation
    # allowed, some clouds take its approximate sums instead (they have tests of their own).
    monkeypatch.setattr("pipeline.estimation.correspondences.AGGREGATE_FRACTION", 0.0)
    # A generator of its own: the case does not depend on which tests ran before.
    rng = np.random.default_rng(23)
    points = rng.uniform(-0.03, 0.03, (3000, 3))
    taxels = rng.uniform(-0.02, 0.02, (5, 3))
    window = normal_ellipsoids(rng.normal(size=(5, 3)), 0.004, 0.0015)
    # A plane offset std of 30 mm: the back's gates cover the whole cloud.
    state_covariance = np.diag([0.05, 0.01, 0.01, 0.01, 0.03, 0.3]) ** 2
    found = find_correspondences(
        PointIndex(points),
        points,
        G,
        PIVOT,
        taxels,
        window,
        state_covariance,
        alternative=False,
        need_pairs=need_pairs,
    )
    assert found.complete() == need_pairs
    assert not found.back.complete or need_pairs
    active = np.zeros(len(points), dtype=bool)
    for side in found.sides():
        covariance = side_covariances(taxels, window, G, PIVOT, state_covariance, side.back)
        images = apply_side(points, G, PIVOT, side.back)
        for i in range(len(taxels)):
            expected = _gated_densities(images, taxels[i], covariance[i])
            active |= expected > 0
            assert side.mass[i] == pytest.approx(expected.sum(), rel=1e-9)
            np.testing.assert_allclose(side.weighted_sum[i], expected @ points, rtol=1e-9)
    np.testing.assert_array_equal(found.active_points(), np.flatnonzero(active))
