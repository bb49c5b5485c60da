"""Perception kernels: from a depth image to a segmented object, its table and its symmetry.

Pure functions on numpy arrays (no PyBullet, no open3d, no file I/O; their pictures are in
:mod:`pipeline.reports.trial_pictures` and :mod:`pipeline.reports.figures`), all in the robot
frame ``R`` (z up) unless a name says otherwise:

* :mod:`.depth` - back-projecting a depth image to points, projecting points into it;
* :mod:`.table` - table plane (RANSAC or known height) and height above it;
* :mod:`.support` - the support plane and a robot frame for a capture that has none;
* :mod:`.clustering` - DBSCAN / Euclidean clustering and voxel subsampling;
* :mod:`.segmentation` - the full cut: table, height filter, largest cluster;
* :mod:`.surfaces` - convex surface regions of a depth image, for scenes of many objects;
* :mod:`.principal_axes` - PCA of a cloud projected onto the table;
* :mod:`.visibility` - visibility-constraint scoring of mirror-plane hypotheses (VC);
* :mod:`.symmetry_from_contacts` - plane offset and bias from a parallel grasp (PS);
* :mod:`.after_view` - the camera's second look while the hand holds the object, the hand masked.

Grasps are planned in :mod:`pipeline.planning`.
"""

from pipeline.perception.clustering import (
    dbscan_labels,
    largest_cluster_indices,
    voxel_subsample_indices,
)
from pipeline.perception.depth import backproject_depth, project_points
from pipeline.perception.principal_axes import TableAxes, table_axes
from pipeline.perception.segmentation import SegmentationResult, segment_points
from pipeline.perception.table import TablePlane, fit_table_ransac, table_from_height
from pipeline.perception.visibility import PlaneGrid, plane_grid, visibility_violations

__all__ = [
    "PlaneGrid",
    "SegmentationResult",
    "TableAxes",
    "TablePlane",
    "backproject_depth",
    "dbscan_labels",
    "fit_table_ransac",
    "largest_cluster_indices",
    "plane_grid",
    "project_points",
    "segment_points",
    "table_axes",
    "table_from_height",
    "visibility_violations",
    "voxel_subsample_indices",
]
