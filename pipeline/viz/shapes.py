"""Geometry the recording draws that no run file holds: the symmetry plane as a quad over
the model (frame R, metres). The hand's links come from the run's world
(:meth:`pipeline.stages.World.hand_meshes`)."""

from __future__ import annotations

import numpy as np

from pipeline.types import SymmetryPlane

#: The plane quad reaches this far beyond the model on each side (m).
PLANE_MARGIN_M = 0.015


def plane_quad(plane: SymmetryPlane, points: np.ndarray) -> np.ndarray:
    """``(4, 3)`` corners of the part of a vertical plane that spans ``points``: along the
    plane as far as the points reach plus :data:`PLANE_MARGIN_M`, from their lowest to their
    highest point, centred on their centroid's projection."""
    normal = plane.normal
    along = np.array([-normal[1], normal[0], 0.0])
    centre = points.mean(axis=0)
    centre = centre - (centre @ normal - plane.offset_m) * normal
    reach = np.abs((points - centre) @ along).max() + PLANE_MARGIN_M
    low, high = points[:, 2].min(), points[:, 2].max()
    corners = []
    for side, z in ((-1, low), (1, low), (1, high), (-1, high)):
        corner = centre + side * reach * along
        corners.append([corner[0], corner[1], z])
    return np.array(corners)
