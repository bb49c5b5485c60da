"""Which cloud points a taxel may touch: a surface-orientation filter on the correspondences.

A gate wider than the distance to an edge of the object takes in points of the adjacent face:
a taxel on the top row of a pad gripping a box sees the box's top face too, so its weighted
mean (eq. 9) lies millimetres inside and above the touched face, and it carries the largest
weight mass of its pad (eq. 11). On a box, those top-row residuals drag the bias down and
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

On the front the filter also compares the horizontal direction of the normals (unsigned
azimuth, :data:`AZIMUTH_BAND_DEG` bands, compatible when under 45 deg apart) wherever both
normals are less than 45 deg from horizontal. Unlike the elevation this depends on the state,
but only through the bias yaw (the front map is a rotation about z), whose prior is a few
degrees, so the caller maps the taxel normals into the points' frame and compares labels.
On the Fig. 10 three-finger study, a large bias lands a side finger on the middle of the
seen face, whose surface is far from facing it; explained by it, the fingers drive the yaw
to its divergence bound instead of translating the object. The back's orientation follows
``m_theta`` too, which can be tens of degrees off, so there the azimuth is not compared
(see :func:`facing_labels`).
"""

from __future__ import annotations

import numpy as np

from pipeline.estimation.aggregation import voxel_moments

#: Width of one elevation band (deg).
BAND_DEG = 15.0
#: A point and a taxel are compatible when their elevation bands differ by at most this.
COMPATIBLE_BANDS = 2
#: Number of elevation bands (0 to 90 deg).
ELEVATION_BANDS = int(np.ceil(90.0 / BAND_DEG))
#: Width of one band of the unsigned horizontal direction of a normal (deg, over 0 to 180).
AZIMUTH_BAND_DEG = 15.0
#: Number of azimuth bands; a label with azimuth band ``AZIMUTH_BANDS`` matches any azimuth.
AZIMUTH_BANDS = round(180.0 / AZIMUTH_BAND_DEG)
#: Normals in this elevation band or steeper have no meaningful azimuth.
STEEP_BAND = round(45.0 / BAND_DEG)
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
    return np.minimum(np.floor(elevation_deg / BAND_DEG).astype(np.int64), ELEVATION_BANDS - 1)


def facing_labels(normals: np.ndarray, with_azimuth: bool = True) -> np.ndarray:
    """Label ``elevation band + ELEVATION_BANDS * azimuth band`` of each unit normal, (M,) int.

    The azimuth band bins ``atan2(n_y, n_x) mod 180 deg`` (the sign of a scatter normal is
    unknown); it is ``AZIMUTH_BANDS`` (matches any) for normals of :data:`STEEP_BAND` or
    steeper, and for all of them without ``with_azimuth``. A label whose azimuth band is 0
    equals the plain elevation band.
    """
    elevation = elevation_bands(normals)
    azimuth_deg = np.degrees(np.arctan2(normals[:, 1], normals[:, 0])) % 180.0
    azimuth = np.floor(azimuth_deg / AZIMUTH_BAND_DEG).astype(np.int64) % AZIMUTH_BANDS
    azimuth = np.where(with_azimuth & (elevation < STEEP_BAND), azimuth, AZIMUTH_BANDS)
    return elevation + ELEVATION_BANDS * azimuth


def any_azimuth(labels: np.ndarray) -> np.ndarray:
    """``labels`` with their azimuth band replaced by "any" (:data:`UNKNOWN_BAND` kept)."""
    elevation = np.mod(labels, ELEVATION_BANDS)
    return np.where(
        labels == UNKNOWN_BAND, UNKNOWN_BAND, elevation + ELEVATION_BANDS * AZIMUTH_BANDS
    )


def point_labels(points_m: np.ndarray) -> np.ndarray:
    """:func:`facing_labels` of every point's voxel normal (the scatter's least eigenvector),
    (N,) int (:data:`UNKNOWN_BAND` where the voxel is sparse or not planar)."""
    moments = voxel_moments(points_m, np.full(3, NORMAL_VOXEL_M))
    eigenvalues, eigenvectors = np.linalg.eigh(moments.scatter)
    planar = eigenvalues[:, 0] <= PLANARITY_RATIO * eigenvalues[:, 1]
    trusted = (moments.count >= NORMAL_MIN_POINTS) & planar
    labels = np.where(trusted, facing_labels(eigenvectors[:, :, 0]), UNKNOWN_BAND)
    return labels[moments.voxel_of_point]


def compatible(point_label: np.ndarray, taxel_label: np.ndarray) -> np.ndarray:
    """Broadcast test: may a taxel of ``taxel_label`` touch a point of ``point_label``?

    Labels are :func:`facing_labels` (plain elevation bands are labels with azimuth band 0):
    the elevation bands must differ by at most :data:`COMPATIBLE_BANDS`, and so must the
    azimuth bands (circularly) unless either matches any azimuth.
    """
    point_label, taxel_label = np.asarray(point_label), np.asarray(taxel_label)
    point_azimuth, point_elevation = np.divmod(point_label, ELEVATION_BANDS)
    taxel_azimuth, taxel_elevation = np.divmod(taxel_label, ELEVATION_BANDS)
    apart = np.abs(point_azimuth - taxel_azimuth) % AZIMUTH_BANDS
    azimuth_ok = (
        (point_azimuth == AZIMUTH_BANDS)
        | (taxel_azimuth == AZIMUTH_BANDS)
        | (np.minimum(apart, AZIMUTH_BANDS - apart) <= COMPATIBLE_BANDS)
    )
    elevation_ok = np.abs(point_elevation - taxel_elevation) <= COMPATIBLE_BANDS
    return (point_label == UNKNOWN_BAND) | (elevation_ok & azimuth_ok)
