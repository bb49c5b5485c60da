"""Voxel-aggregated Gaussian sums against exact per-point sums (scipy densities)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from pipeline.estimation.aggregation import (
    gaussian_sums,
    voxel_exponents,
    voxel_moments,
)

GATE = 7.815


def _cylinder_cloud(n_points, seed=0):
    """The visible half of a 40 mm radius, 100 mm tall cylinder with 0.5 mm noise (m)."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(np.pi / 2, 3 * np.pi / 2, n_points)
    points = np.column_stack(
        [0.04 * np.cos(angle), 0.04 * np.sin(angle), rng.uniform(0.0, 0.1, n_points)]
    )
    return points + rng.normal(0.0, 0.0005, points.shape)


def _gates(rng, count, stds_m):
    """Covariances with principal stds ``(horizontal, horizontal, vertical)`` turned by a
    random yaw (like the gates of taxels on vertical pads), centred near the surface."""
    yaws = rng.uniform(0.0, 2.0 * np.pi, count)
    rotations = [
        np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
        for a in yaws
    ]
    covariances = np.array([r @ np.diag(np.square(stds_m)) @ r.T for r in rotations])
    angle = rng.uniform(np.pi / 2, 3 * np.pi / 2, count)
    centres = np.column_stack(
        [0.04 * np.cos(angle), 0.04 * np.sin(angle), rng.uniform(0.02, 0.08, count)]
    )
    return centres + rng.normal(0.0, 0.003, centres.shape), covariances


def _exact(points, centres, covariances):
    mass, weighted = [], []
    for centre, covariance in zip(centres, covariances, strict=True):
        offsets = points - centre
        d2 = np.einsum("ni,ij,nj->n", offsets, np.linalg.inv(covariance), offsets)
        w = np.where(d2 < GATE, multivariate_normal(centre, covariance).pdf(points), 0.0)
        mass.append(w.sum())
        weighted.append(w @ points)
    return np.array(mass), np.array(weighted)


def test_voxel_moments_match_a_direct_grouping():
    points = _cylinder_cloud(2000, seed=1)
    size = np.array([0.004, 0.003, 0.002])
    moments = voxel_moments(points, size)
    assert moments.count.sum() == len(points)
    keys = np.floor(points / size).astype(int)
    for voxel in (0, len(moments.count) // 2, len(moments.count) - 1):
        members = points[moments.voxel_of_point == voxel]
        assert len(np.unique(keys[moments.voxel_of_point == voxel], axis=0)) == 1
        assert moments.count[voxel] == len(members)
        np.testing.assert_allclose(moments.centroid[voxel], members.mean(axis=0), atol=1e-15)
        offsets = members - members.mean(axis=0)
        np.testing.assert_allclose(moments.scatter[voxel], offsets.T @ offsets, atol=1e-15)


def test_voxel_moments_from_given_coordinates_and_label_ranks_are_the_same():
    points = _cylinder_cloud(2000, seed=2)
    labels = np.random.default_rng(2).integers(-1, 5, len(points))
    size = np.array([0.004, 0.003, 0.002])
    plain = voxel_moments(points, size, labels)
    given = voxel_moments(
        points, size, labels, np.ascontiguousarray(points.T), np.unique(labels, return_inverse=True)
    )
    for name in ("count", "centroid", "scatter", "voxel_of_point", "label"):
        np.testing.assert_array_equal(getattr(given, name), getattr(plain, name))
    assert len(np.unique(plain.label)) == 6


@pytest.mark.parametrize("edge_m", [0.02, 0.002])
def test_labelled_voxels_are_the_cells_split_by_label_in_order(edge_m):
    # 0.02 m: few enough cells x labels to key them directly; 0.002 m: keyed through the
    # ranks of the occupied cells. Either way the voxels are the (cell, label) pairs in
    # lexicographic order.
    points = _cylinder_cloud(2000, seed=3)
    labels = np.random.default_rng(3).integers(-1, 5, len(points))
    moments = voxel_moments(points, np.full(3, edge_m), labels)
    cells = np.floor(points / edge_m).astype(np.int64)
    _, expected = np.unique(np.column_stack([cells, labels]), axis=0, return_inverse=True)
    np.testing.assert_array_equal(moments.voxel_of_point, expected.ravel())
    np.testing.assert_array_equal(moments.label[moments.voxel_of_point], labels)


def test_voxel_edges_keep_every_gate_wider_than_the_ratio():
    rng = np.random.default_rng(2)
    _, covariances = _gates(rng, 20, np.array([0.012, 0.006, 0.0025]))
    edges = np.exp2(voxel_exponents(covariances, ratio=0.5) / 4.0)
    scaled = np.einsum("i,tij,j->tij", 1.0 / edges, covariances, 1.0 / edges)
    # ||H C^-1 H|| <= ratio^2  <=>  lambda_min(H^-1 C H^-1) >= 1 / ratio^2
    assert np.linalg.eigvalsh(scaled)[:, 0].min() >= 4.0 - 1e-9
    # ... and not needlessly fine: a quarter octave coarser on every axis breaks the bound.
    assert np.linalg.eigvalsh(scaled * np.exp2(-0.5))[:, 0].min() < 4.0


def test_voxel_edges_follow_each_axis_of_long_thin_gates():
    # Gates long and thin across random horizontal directions (a back gate under a broad
    # plane prior) bound the horizontal edges; the vertical std alone bounds the vertical
    # edge, to within the quarter-octave rounding.
    rng = np.random.default_rng(5)
    _, covariances = _gates(rng, 30, np.array([0.07, 0.01, 0.0026]))
    edges = np.exp2(voxel_exponents(covariances, ratio=0.5) / 4.0)
    scaled = np.einsum("i,tij,j->tij", 1.0 / edges, covariances, 1.0 / edges)
    assert np.linalg.eigvalsh(scaled)[:, 0].min() >= 4.0 - 1e-9
    assert edges[2] >= 0.5 * 0.0026 * np.exp2(-0.25)
    assert edges[:2].max() <= 0.5 * 0.01


@pytest.mark.parametrize(
    "stds_mm", [(12.0, 8.0, 3.0), (30.0, 10.0, 2.6), (70.0, 10.0, 2.6), (5.0, 4.0, 3.0)]
)
def test_aggregated_sums_match_the_exact_sums(stds_mm):
    rng = np.random.default_rng(3)
    points = _cylinder_cloud(20000, seed=4)
    centres, covariances = _gates(rng, 12, 1e-3 * np.array(stds_mm))
    normaliser = 1.0 / np.sqrt((2.0 * np.pi) ** 3 * np.linalg.det(covariances))
    moments = voxel_moments(points, np.exp2(voxel_exponents(covariances) / 4.0))
    assert len(moments.count) < len(points) / 2  # the aggregation does reduce the cloud
    mass, weighted, inside = gaussian_sums(moments, centres, covariances, normaliser)
    exact_mass, exact_weighted = _exact(points, centres, covariances)
    supported = exact_mass > 1e-3 * exact_mass.max()
    np.testing.assert_allclose(mass[supported], exact_mass[supported], rtol=0.01)
    means = weighted[supported] / mass[supported, None]
    exact_means = exact_weighted[supported] / exact_mass[supported, None]
    # A tenth of the gate's smallest std (0.26-0.3 mm here, against 2 mm sensor noise).
    assert np.abs(means - exact_means).max() < 0.1e-3 * min(stds_mm)
    # Every point inside some gate lies in a voxel flagged as inside (up to boundary voxels).
    d2 = np.stack(
        [
            np.einsum("ni,ij,nj->n", points - c, np.linalg.inv(cov), points - c)
            for c, cov in zip(centres, covariances, strict=True)
        ]
    )
    deep_inside = (d2 < 0.5 * GATE).any(axis=0)
    assert inside[moments.voxel_of_point[deep_inside]].all()
