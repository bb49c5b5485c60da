"""Evaluation metrics of a completed object model (docs/method.md §6), by concern:

* :mod:`.fits` - :func:`fit_circle_taubin` (diameter of cylinders), :func:`fit_line_irls`
  (robust orthogonal line), :func:`box_thickness` (thickness and side angle of a box-like
  object), :func:`diameter_error`;
* :mod:`.deviation` - :func:`point_to_mesh_distances` / :class:`DeviationSummary`: the
  geometric deviation of every completed point from the ground-truth mesh surface
  (:class:`MeshSurface`: one mesh asked about several point sets);
* :mod:`.shape_scores` - :func:`surface_scores` (Chamfer distance, F-score at
  :data:`FSCORE_THRESHOLDS_M`) and :func:`hull_iou` (volumetric IoU on a grid);
* :mod:`.mesh_queries` - where lines along a coordinate axis cross a mesh (the inside
  tests of the solids and the IoU).

Pure functions on point arrays in the robot frame ``R`` (metres, radians); exact
point-to-triangle distances come from libigl's AABB tree (float64), the inside tests from
numpy: the evaluation does not load open3d.
"""

from __future__ import annotations

from pipeline.metrics.deviation import (
    DeviationSummary,
    MeshSurface,
    mesh_deviation,
    mesh_occupancy,
    point_to_mesh_distances,
)
from pipeline.metrics.fits import (
    MAD_TO_SIGMA,
    TUKEY_C,
    CircleFit,
    LineFit,
    ThicknessFit,
    box_thickness,
    diameter_error,
    fit_circle_taubin,
    fit_line_irls,
    plane_after_bias,
    side_wall,
)
from pipeline.metrics.shape_scores import (
    FSCORE_THRESHOLDS_M,
    SolidGrid,
    grid_order,
    hull_iou,
    nearest_distances,
    sample_surface,
    solid_grid,
    solid_share_inside,
    support_faces,
    surface_scores,
    threshold_label,
)

__all__ = [
    "FSCORE_THRESHOLDS_M",
    "MAD_TO_SIGMA",
    "TUKEY_C",
    "CircleFit",
    "DeviationSummary",
    "LineFit",
    "MeshSurface",
    "SolidGrid",
    "ThicknessFit",
    "box_thickness",
    "diameter_error",
    "fit_circle_taubin",
    "fit_line_irls",
    "grid_order",
    "hull_iou",
    "mesh_deviation",
    "mesh_occupancy",
    "nearest_distances",
    "plane_after_bias",
    "point_to_mesh_distances",
    "sample_surface",
    "side_wall",
    "solid_grid",
    "solid_share_inside",
    "support_faces",
    "surface_scores",
    "threshold_label",
]
