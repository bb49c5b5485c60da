"""Perception kernels: from a depth image to a segmented object, its symmetry and a top grasp.

Pure functions on numpy arrays (no PyBullet, no open3d, no file I/O; their pictures are in
:mod:`pipeline.trial_pictures` and :mod:`pipeline.figures`), all in the robot frame ``R``
(z up) unless a name says otherwise:

* :mod:`.depth` - back-projecting a depth image to points, projecting points into it;
* :mod:`.table` - table plane (RANSAC or known height) and height above it;
* :mod:`.clustering` - DBSCAN / Euclidean clustering and voxel subsampling;
* :mod:`.segmentation` - the full cut: table, height filter, largest cluster;
* :mod:`.principal_axes` - PCA of a cloud projected onto the table;
* :mod:`.visibility` - visibility-constraint scoring of mirror-plane hypotheses (VC);
* :mod:`.symmetry_from_contacts` - plane offset and bias from a parallel grasp (PS);
* :mod:`.grasp_geometry` - top grasps for parallel and three-finger hands;
* :mod:`.synthetic` - analytic ray casting of simple objects, for tests and benchmarks.
"""

from .clustering import dbscan_labels, largest_cluster_indices, voxel_subsample_indices
from .depth import backproject_depth, project_points
from .principal_axes import TableAxes, table_axes
from .segmentation import SegmentationResult, segment_points
from .table import TablePlane, fit_table_ransac, table_from_height
from .visibility import PlaneGrid, plane_grid, visibility_violations

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
