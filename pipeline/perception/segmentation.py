"""Cutting one object out of a scene cloud (paper section 6.2.1).

Drop everything lower than ``min_height_m`` above the table (the table itself and what lies
on it flat), optionally thin the rest on a voxel grid, cluster it and keep the largest
cluster.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .clustering import dbscan_labels, largest_cluster_indices, voxel_subsample_indices
from .table import TablePlane


@dataclass(frozen=True)
class SegmentationResult:
    """Which scene points were kept, and why.

    Attributes:
        indices: ``(K,)`` indices of the object's points in the input cloud.
        above_table: how many points survived the height filter (before subsampling).
        clusters: how many clusters the clustering found.
    """

    indices: np.ndarray
    above_table: int
    clusters: int


def segment_points(
    points_robot: np.ndarray,
    table: TablePlane,
    *,
    min_height_m: float = 0.02,
    max_height_m: float = np.inf,
    eps_m: float = 0.01,
    min_points: int = 10,
    voxel_m: float = 0.0,
) -> SegmentationResult:
    """Segment the largest object standing on ``table``.

    Args:
        points_robot: ``(N, 3)`` scene points in the robot frame, metres.
        table: the supporting plane.
        min_height_m: points lower than this above the table are dropped.
        max_height_m: points higher than this above the table are dropped.
        eps_m: DBSCAN neighbourhood radius.
        min_points: DBSCAN core-point threshold (self included); 1 = Euclidean clustering.
        voxel_m: voxel side for subsampling before clustering (0: keep every point).

    Returns:
        The kept indices (empty when nothing is left) and counts for error messages.
    """
    height = table.height_m(points_robot)
    above = np.flatnonzero((height >= min_height_m) & (height <= max_height_m))
    kept = above[voxel_subsample_indices(points_robot[above], voxel_m)]
    labels = dbscan_labels(points_robot[kept], eps_m, min_points)
    clusters = int(labels.max()) + 1 if len(labels) else 0
    return SegmentationResult(
        indices=kept[largest_cluster_indices(labels)], above_table=len(above), clusters=clusters
    )
