"""PCA of a cloud projected onto the table (paper section 4): major and minor axes.

Sign convention (so results are reproducible): the major axis ``e_a`` has its angle about
+z in ``(-pi/2, pi/2]``; the minor axis is ``e_b = R_z(+90 deg) e_a``. Both are horizontal
unit vectors in the robot frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.types import SymmetryPlane


@dataclass(frozen=True)
class TableAxes:
    """Principal axes of a cloud's footprint on the table.

    Attributes:
        centroid_m: ``(3,)`` mean of the points (x, y: footprint centroid ``c``; z: mean
            height), robot frame.
        major: ``(3,)`` horizontal unit major axis ``e_a``.
        minor: ``(3,)`` horizontal unit minor axis ``e_b``.
        variances_m2: ``(2,)`` footprint variance along ``e_a`` and ``e_b``.
    """

    centroid_m: np.ndarray
    major: np.ndarray
    minor: np.ndarray
    variances_m2: np.ndarray

    @property
    def major_angle_rad(self) -> float:
        """Angle of ``e_a`` about +z."""
        return float(np.arctan2(self.major[1], self.major[0]))

    @property
    def minor_angle_rad(self) -> float:
        """Angle of ``e_b`` about +z (the normal angle of the PCA symmetry plane)."""
        return float(np.arctan2(self.minor[1], self.minor[0]))


def table_axes(points_robot: np.ndarray) -> TableAxes:
    """PCA of the ``(N, 3)`` points' horizontal coordinates (N >= 2)."""
    points = np.asarray(points_robot, dtype=np.float64)
    if len(points) < 2:
        raise ValueError(f"PCA needs at least 2 points, got {len(points)}")
    centroid = points.mean(axis=0)
    xy = points[:, :2] - centroid[:2]
    variances, vectors = np.linalg.eigh(xy.T @ xy / len(points))
    major_xy = vectors[:, 1]
    angle = np.arctan2(major_xy[1], major_xy[0])
    if angle <= -np.pi / 2 or angle > np.pi / 2:
        major_xy = -major_xy
    major = np.array([major_xy[0], major_xy[1], 0.0])
    minor = np.array([-major_xy[1], major_xy[0], 0.0])
    return TableAxes(
        centroid_m=centroid, major=major, minor=minor, variances_m2=variances[::-1].copy()
    )


def pca_plane(points_robot: np.ndarray) -> SymmetryPlane:
    """The PCA symmetry plane: it contains the major axis ``e_a`` and z (normal ``e_b``) and
    passes through the centroid of the (visible) points."""
    axes = table_axes(points_robot)
    return SymmetryPlane(axes.minor_angle_rad, float(axes.minor @ axes.centroid_m))
