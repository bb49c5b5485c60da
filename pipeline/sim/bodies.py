"""The scene's bodies as the engines share them: the table's size and colours, an object's
mass properties, and when an object counts as settled. No simulator is imported here.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

#: Half-extents of the table box (m): 2 m x 2 m, 5 cm thick.
TABLE_HALF_EXTENTS_M = (1.0, 1.0, 0.025)
#: Colours (RGBA, 0-1) of the table and of an object built from a mesh.
TABLE_RGBA = (0.55, 0.45, 0.35, 1.0)
OBJECT_RGBA = (0.2, 0.45, 0.8, 1.0)

#: Physics steps (1/240 s each) an object is left to settle after being placed, and how
#: many more it is given at most while it still moves (a mesh placed where it topples):
#: the camera looks once it is still.
SETTLE_STEPS = 24
MAX_SETTLE_STEPS = 480
#: Speeds below which an object counts as still (m/s, rad/s).
REST_SPEED_M_S = 1e-3
REST_SPIN_RAD_S = 1e-2


def mass_properties(
    mesh: trimesh.Trimesh, mass_kg: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre of mass, principal-axes orientation (quaternion xyzw) and principal moments
    (kg m^2) of a uniform solid ``mesh`` of ``mass_kg`` (mesh frame, m); its bounding box
    stands in for a mesh that does not enclose a volume."""
    solid = mesh if mesh.is_volume else mesh.bounding_box
    solid = solid.copy()
    solid.density = mass_kg / solid.volume
    moments, axes = np.linalg.eigh(solid.moment_inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 0] = -axes[:, 0]
    return solid.center_mass, Rotation.from_matrix(axes).as_quat(), moments
