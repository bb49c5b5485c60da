"""Clustering (scipy) and subsampling (open3d) of point clouds.

open3d is imported where it is used: :mod:`pipeline.perception` loads this module, and the
plugins that import from that package must stay quick to import (``symfuse plugins``).
"""

from __future__ import annotations

import numpy as np


def _cloud(points: np.ndarray):
    from pipeline.io.open3d_loader import open3d

    o3d = open3d()
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))


def dbscan_labels(points: np.ndarray, eps_m: float, min_points: int) -> np.ndarray:
    """DBSCAN cluster labels ``(N,)`` int: 0, 1, ... per cluster, -1 for noise.

    A point is *core* when at least ``min_points`` points, itself included, lie within
    ``eps_m``; clusters are the connected components of core points linked by ``eps_m``,
    numbered in the order of their first core point; a non-core point within ``eps_m`` of
    a core point joins the cluster of the nearest one; the rest is noise. (open3d's
    ``cluster_dbscan`` gives such a border point to whichever cluster reaches it first,
    which depends on the order of the points; the nearest core point makes the
    segmentation of a scene independent of how its points are ordered.) With
    ``min_points = 1`` it is plain Euclidean (single-linkage) clustering. Written on
    scipy's k-d tree and graph components: the same partition as open3d's, without
    loading open3d.

    Args:
        points: ``(N, 3)`` coordinates (metres).
        eps_m: neighbourhood radius.
        min_points: neighbours (self included) that make a point core.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    labels = np.full(len(points), -1, dtype=np.int64)
    # Every pair within eps_m once (one dual-tree search, cheaper than counting each
    # point's ball): a point's neighbours are its pairs and itself, and the core points'
    # links are the pairs of two core points.
    pairs = cKDTree(points).query_pairs(eps_m, output_type="ndarray").reshape(-1, 2)
    is_core = np.bincount(pairs.ravel(), minlength=len(points)) + 1 >= min_points
    core = np.flatnonzero(is_core)
    if len(core) == 0:
        return labels
    position = np.cumsum(is_core) - 1  # a core point's index among the core points
    links = position[pairs[is_core[pairs].all(axis=1)]]
    graph = coo_matrix(
        (np.ones(len(links), dtype=np.int8), (links[:, 0], links[:, 1])),
        shape=(len(core), len(core)),
    )
    _, component = connected_components(graph, directed=False)
    # Components are numbered by their first core point (core is sorted by index).
    _, first = np.unique(component, return_index=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    labels[core] = rank[component]
    others = np.flatnonzero(~is_core)
    if len(others):
        distance, nearest = cKDTree(points[core]).query(points[others])
        border = distance <= eps_m
        labels[others[border]] = labels[core[nearest[border]]]
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

    The voxels are open3d's (``voxel_down_sample_and_trace``) on the grid of multiples of
    ``voxel_m`` in frame R, so a point's voxel does not depend on the rest of the cloud.
    Returns sorted indices into ``points``, so per-point data (pixels) can follow.
    """
    points = np.asarray(points, dtype=np.float64)
    if voxel_m <= 0.0 or len(points) == 0:
        return np.arange(len(points))
    # open3d's voxels start at min_bound: put it on the grid, at or below every point.
    low = np.floor(points.min(axis=0) / voxel_m) * voxel_m
    high = points.max(axis=0) + voxel_m
    means, _, members = _cloud(points).voxel_down_sample_and_trace(voxel_m, low, high, False)
    sizes = np.array([len(member) for member in members])
    index = np.concatenate([np.asarray(member) for member in members])
    voxel = np.repeat(np.arange(len(sizes)), sizes)
    distance = np.linalg.norm(points[index] - np.asarray(means.points)[voxel], axis=1)
    order = np.lexsort((index, distance, voxel))
    first = np.ones(len(order), dtype=bool)
    first[1:] = voxel[order][1:] != voxel[order][:-1]
    return np.sort(index[order[first]])
