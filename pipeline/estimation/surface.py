"""Which cloud points a taxel may touch: a surface-orientation filter on the correspondences.

A gate wider than the distance to an edge of the object takes in points of the adjacent face:
a taxel on the top row of a pad gripping a box sees the box's top face too, so its weighted
mean (eq. 9) lies millimetres inside and above the touched face, and it carries the largest
weight mass of its pad (eq. 11). Measured on a 45 x 120 x 100 mm brick and on the CD drive,
those top-row residuals (up to 9 mm along the normal, 2 mm vertically) drag the bias down and
the plane sideways; vertical faces do not observe ``b_z`` well enough to resist.

A pad can only touch a face roughly parallel to it, so a point corresponds to a taxel only
when their surface normals have similar elevation (angle from the horizontal plane), a
property the bias and the mirror (rotations about z and reflections in vertical planes)
leave unchanged, so the filter does not depend on the state. Elevations are binned in
:data:`BAND_DEG` bands; a point and a taxel are compatible when their bands differ by at most
:data:`COMPATIBLE_BANDS` (under 45 deg apart). Point normals come from the scatter of the
points in :data:`NORMAL_VOXEL_M` voxels (``O(N)``, once per cloud); a voxel with too few points
or no clear plane gives its points the band :data:`UNKNOWN_BAND`, compatible with every taxel,
so the filter only ever removes points it is confident about. This departs from the paper's
eq. 9, which weighs every point by distance alone.
"""

from __future__ import annotations

import numpy as np

from .aggregation import voxel_moments

#: Width of one elevation band (deg).
BAND_DEG = 15.0
#: A point and a taxel are compatible when their elevation bands differ by at most this.
COMPATIBLE_BANDS = 2
#: Band of points whose normal is not known; compatible with every taxel.
UNKNOWN_BAND = -1
#: Edge of the voxels whose scatter gives the point normals (m).
NORMAL_VOXEL_M = 0.01
#: Fewest points in a voxel for its normal to be trusted.
NORMAL_MIN_POINTS = 5
#: Largest ratio of the smallest to the middle scatter eigenvalue for a voxel to be planar.
PLANARITY_RATIO = 0.3


def elevation_bands(normals: np.ndarray) -> np.ndarray:
    """Band index of each unit normal's elevation ``asin(|n_z|)``, (M,) int."""
    elevation_deg = np.degrees(np.arcsin(np.clip(np.abs(normals[:, 2]), 0.0, 1.0)))
    last = int(np.ceil(90.0 / BAND_DEG)) - 1
    return np.minimum(np.floor(elevation_deg / BAND_DEG).astype(np.int64), last)


def point_bands(points_m: np.ndarray) -> np.ndarray:
    """Elevation band of every point from its voxel's scatter, (N,) int (see the module
    docstring; :data:`UNKNOWN_BAND` where the voxel is sparse or not planar)."""
    moments = voxel_moments(points_m, np.full(3, NORMAL_VOXEL_M))
    eigenvalues, eigenvectors = np.linalg.eigh(moments.scatter)
    normals = eigenvectors[:, :, 0]
    bands = elevation_bands(normals)
    planar = eigenvalues[:, 0] <= PLANARITY_RATIO * eigenvalues[:, 1]
    trusted = (moments.count >= NORMAL_MIN_POINTS) & planar
    return np.where(trusted, bands, UNKNOWN_BAND)[moments.voxel_of_point]


def compatible(point_band: np.ndarray, taxel_band: np.ndarray) -> np.ndarray:
    """Broadcast test: may a taxel of ``taxel_band`` touch a point of ``point_band``?"""
    return (point_band == UNKNOWN_BAND) | (np.abs(point_band - taxel_band) <= COMPATIBLE_BANDS)
