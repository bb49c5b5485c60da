"""Rotations about the vertical and camera poses that look at a point (frame ``R``: robot
base, z up; angles in radians, lengths in metres).

Camera poses follow the OpenCV optical convention (x right, y down, z along the optical
axis) and are returned as ``T_robot_camera``, the 4x4 transform from camera to robot
coordinates.
"""

from __future__ import annotations

import numpy as np


def rotation_z(theta_rad: float) -> np.ndarray:
    """``R_z(theta)``: rotation by ``theta_rad`` about +z (counter-clockwise seen from
    above), ``(3, 3)``."""
    c, s = np.cos(theta_rad), np.sin(theta_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def look_at(
    target_m: np.ndarray, distance_m: float, elevation_rad: float, azimuth_rad: float
) -> np.ndarray:
    """``T_robot_camera`` of a camera ``distance_m`` from ``target_m``, looking at it.

    The camera sits at ``target + distance (cos el cos az, cos el sin az, sin el)``: azimuth
    about +z from the robot's +x axis, elevation up from the horizontal. The image x axis
    stays horizontal (no roll), so the vertical projects to the image's up direction.
    Defined for every elevation, including straight down (``pi / 2``).
    """
    direction_to_camera = np.array(
        [
            np.cos(elevation_rad) * np.cos(azimuth_rad),
            np.cos(elevation_rad) * np.sin(azimuth_rad),
            np.sin(elevation_rad),
        ]
    )
    z_axis = -direction_to_camera
    x_axis = np.array([-np.sin(azimuth_rad), np.cos(azimuth_rad), 0.0])
    y_axis = np.cross(z_axis, x_axis)
    transform = np.eye(4)
    transform[:3, :3] = np.column_stack([x_axis, y_axis, z_axis])
    transform[:3, 3] = np.asarray(target_m, dtype=np.float64) + distance_m * direction_to_camera
    return transform
