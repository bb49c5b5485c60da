"""Clustering and subsampling of point clouds (scipy k-d tree; no open3d).

scipy is imported where it is used: :mod:`pipeline.perception` loads this module, and the
plugins that import from that package must stay quick to import (``symfuse plugins``).

``dbscan_labels`` follows the usual DBSCAN definition (the same as open3d's
``cluster_dbscan``): a point is *core* when at least ``min_points`` points, itself
included, lie within ``eps_m``; clusters are the connected components of core points
linked by ``eps_m``; a non-core point within ``eps_m`` of a core point joins that core
point's cluster (the nearest such core point when there are several); the rest is noise.
With ``min_points = 1`` it is plain Euclidean (single-linkage) clustering.
"""

from __future__ import annotations

import numpy as np


def dbscan_labels(points: np.ndarray, eps_m: float, min_points: int) -> np.ndarray:
    """DBSCAN cluster labels ``(N,)`` int: 0, 1, ... per cluster, -1 for noise.

    Args:
        points: ``(N, D)`` coordinates (metres).
        eps_m: neighbourhood radius.
        min_points: neighbours (self included) that make a point core.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    n = len(points)
    labels = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return labels
    tree = cKDTree(points)
    pairs = tree.query_pairs(eps_m, output_type="ndarray")
    counts = 1 + np.bincount(pairs.ravel(), minlength=n)
    core = counts >= min_points
    both_core = core[pairs[:, 0]] & core[pairs[:, 1]]
    core_pairs = pairs[both_core]
    graph = coo_matrix(
        (np.ones(len(core_pairs)), (core_pairs[:, 0], core_pairs[:, 1])), shape=(n, n)
    )
    _, component = connected_components(graph, directed=False)
    core_index = np.flatnonzero(core)
    # Renumber the components that contain core points 0..K-1 by first appearance.
    _, first, inverse = np.unique(component[core_index], return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))
    labels[core_index] = order[inverse]
    border = np.flatnonzero(~core)
    if len(border) and len(core_index):
        distance, nearest = cKDTree(points[core_index]).query(
            points[border], distance_upper_bound=eps_m
        )
        attached = np.isfinite(distance)
        labels[border[attached]] = labels[core_index[nearest[attached]]]
    return labels


def largest_cluster_indices(labels: np.ndarray) -> np.ndarray:
    """Indices of the points in the most populous cluster (empty when all are noise)."""
    labels = np.asarray(labels)
    clustered = labels[labels >= 0]
    if len(clustered) == 0:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(labels == np.argmax(np.bincount(clustered)))


def voxel_subsample_indices(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """Keep one point per cubic voxel of side ``voxel_m``: the one nearest the voxel's mean.

    Returns sorted indices into ``points``, so per-point data (pixels) can follow.
    """
    points = np.asarray(points, dtype=np.float64)
    if voxel_m <= 0.0 or len(points) == 0:
        return np.arange(len(points))
    keys = np.floor(points / voxel_m).astype(np.int64)
    _, voxel, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    voxel = voxel.reshape(-1)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, voxel, points)
    distance = np.linalg.norm(points - (sums / counts[:, None])[voxel], axis=1)
    order = np.lexsort((distance, voxel))
    first = np.ones(len(order), dtype=bool)
    first[1:] = voxel[order][1:] != voxel[order][:-1]
    return np.sort(order[first])
