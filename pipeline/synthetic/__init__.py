"""Analytic scenes with known truth, for the synthetic studies, tests and benchmarks.

* :mod:`.cylinder`: a vertical cylinder seen once by a depth camera (ray-traced cloud).
* :mod:`.cases`: a whole synthetic trial on that cylinder: the cloud, the contacts of one
  top grasp moved by a true bias, and the true and perturbed symmetry planes
  (:func:`make_case`, the paper's Figs. 8-10).
* :mod:`.tabletop`: depth images of unions of boxes and elliptic cylinders standing on a
  table (segmentation, initialiser and planner tests).

Everything is pure numpy: no simulator, no files.
"""

from __future__ import annotations

from pipeline.synthetic.cases import (
    PAD_NAMES,
    GripperKind,
    PadGeometry,
    SyntheticCase,
    TouchSettings,
    make_case,
    move_contacts,
    perturbed_plane,
    touch_pads,
)
from pipeline.synthetic.cylinder import (
    Cylinder,
    CylinderView,
    Viewpoint,
    camera_direction,
    cylinder_mesh,
    render_cylinder,
)
from pipeline.synthetic.tabletop import (
    SyntheticObject,
    box_object,
    cylinder_object,
    place,
    render_depth,
    sample_surface,
    spray_bottle_object,
    synthetic_observation,
)

__all__ = [
    "PAD_NAMES",
    "Cylinder",
    "CylinderView",
    "GripperKind",
    "PadGeometry",
    "SyntheticCase",
    "SyntheticObject",
    "TouchSettings",
    "Viewpoint",
    "box_object",
    "camera_direction",
    "cylinder_mesh",
    "cylinder_object",
    "make_case",
    "move_contacts",
    "perturbed_plane",
    "place",
    "render_cylinder",
    "render_depth",
    "sample_surface",
    "spray_bottle_object",
    "synthetic_observation",
    "touch_pads",
]
