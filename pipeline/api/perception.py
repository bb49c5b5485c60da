"""Perception kernels the built-in stages are made of: depth geometry, the table,
segmentation, principal axes, visibility of mirror-plane hypotheses.

What is named here keeps its meaning across releases, as :mod:`pipeline.api` does.
Each name loads its module when it is first imported, so a plugin pays only for the
kernels it uses (``symfuse plugins`` imports every plugin and must stay quick).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipeline.api._lazy import lazy_attributes

if TYPE_CHECKING:
    from pipeline.perception.principal_axes import pca_plane, table_axes
    from pipeline.perception.segmentation import segment_image, segment_points
    from pipeline.perception.support import fit_support_plane, frame_on_plane
    from pipeline.perception.symmetry_from_contacts import contact_bias, jaw_centre_offset
    from pipeline.perception.table import TablePlane, measure_table, resolve_table
    from pipeline.perception.visibility import plane_grid, visibility_violations

#: Where each name comes from: (module, name there).
_SOURCES = {
    "TablePlane": ("pipeline.perception.table", "TablePlane"),
    "contact_bias": ("pipeline.perception.symmetry_from_contacts", "contact_bias"),
    "fit_support_plane": ("pipeline.perception.support", "fit_support_plane"),
    "frame_on_plane": ("pipeline.perception.support", "frame_on_plane"),
    "jaw_centre_offset": ("pipeline.perception.symmetry_from_contacts", "jaw_centre_offset"),
    "measure_table": ("pipeline.perception.table", "measure_table"),
    "pca_plane": ("pipeline.perception.principal_axes", "pca_plane"),
    "plane_grid": ("pipeline.perception.visibility", "plane_grid"),
    "resolve_table": ("pipeline.perception.table", "resolve_table"),
    "segment_image": ("pipeline.perception.segmentation", "segment_image"),
    "segment_points": ("pipeline.perception.segmentation", "segment_points"),
    "table_axes": ("pipeline.perception.principal_axes", "table_axes"),
    "visibility_violations": ("pipeline.perception.visibility", "visibility_violations"),
}

__all__ = [
    "TablePlane",
    "contact_bias",
    "fit_support_plane",
    "frame_on_plane",
    "jaw_centre_offset",
    "measure_table",
    "pca_plane",
    "plane_grid",
    "resolve_table",
    "segment_image",
    "segment_points",
    "table_axes",
    "visibility_violations",
]


__getattr__ = lazy_attributes(__name__, globals(), _SOURCES)
