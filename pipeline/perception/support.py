"""A robot frame for a capture that has none: the support plane (table or floor) and a frame
standing on it.

The frame built here, ``R``, has z along the plane's normal pointing toward the camera
(up), its origin on the plane (at the foot of the camera until :func:`recentre` moves it
below an object) and x along the camera's optical axis projected onto the plane, so a
robot-frame picture seen from above shows the scene as the camera looked at it, from
the bottom of the picture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .table import refit_until_settled


@dataclass(frozen=True)
class SupportPlane:
    """The plane ``{p : normal . p = offset_m}`` in the camera frame, ``normal`` a unit
    vector pointing to the camera's side; ``inliers`` is how many points lie on it."""

    normal: np.ndarray
    offset_m: float
    inliers: int


def fit_support_plane(
    points_camera: np.ndarray,
    *,
    inlier_distance_m: float = 0.01,
    iterations: int = 1000,
    voxel_m: float = 0.01,
    seed: int = 0,
) -> SupportPlane:
    """The dominant plane of a scene (open3d RANSAC), refitted to its inliers by least
    squares, its normal turned toward the camera at the origin.

    RANSAC runs on a ``voxel_m`` grid so that near and far surfaces weigh by area rather
    than by how many pixels they fill; the inliers are then counted on every point.

    Raises:
        ValueError: fewer than 3 points, or the plane passes through the camera.
    """
    from pipeline.open3d_loader import open3d

    o3d = open3d()
    points = np.asarray(points_camera, dtype=np.float64)
    if len(points) < 3:
        raise ValueError(f"a plane needs at least 3 points, got {len(points)}")
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if voxel_m > 0.0:
        cloud = cloud.voxel_down_sample(voxel_m)
    if len(cloud.points) < 3:
        raise ValueError("fewer than 3 points are left on the voxel grid")
    o3d.utility.random.seed(seed)
    model, _ = cloud.segment_plane(
        distance_threshold=inlier_distance_m, ransac_n=3, num_iterations=iterations
    )
    normal = np.asarray(model[:3], dtype=np.float64)
    offset = -float(model[3])
    scale = float(np.linalg.norm(normal))
    normal, offset = normal / scale, offset / scale
    normal, offset, _ = refit_until_settled(points, normal, offset, inlier_distance_m)
    # Camera at the origin: its height above the plane is -offset along the normal.
    if offset > 0.0:
        normal, offset = -normal, -offset
    if -offset < inlier_distance_m:
        raise ValueError("the dominant plane passes through the camera")
    inliers = np.abs(points @ normal - offset) < inlier_distance_m
    return SupportPlane(normal=normal, offset_m=offset, inliers=int(inliers.sum()))


def frame_on_plane(plane: SupportPlane) -> np.ndarray:
    """``T_robot_camera`` of the frame standing on ``plane`` (see the module docstring).

    When the camera looks straight down, the image's downward axis (+y) projected on the
    plane is used as x instead of the optical axis.
    """
    up = plane.normal
    for axis in (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])):
        forward = axis - (axis @ up) * up
        if np.linalg.norm(forward) > 1e-3:
            break
    x_axis = forward / np.linalg.norm(forward)
    y_axis = np.cross(up, x_axis)
    T_camera_robot = np.eye(4)
    T_camera_robot[:3, :3] = np.column_stack([x_axis, y_axis, up])
    T_camera_robot[:3, 3] = plane.offset_m * up  # the camera's foot on the plane
    return np.linalg.inv(T_camera_robot)


def recentre(T_robot_camera: np.ndarray, point_robot: np.ndarray) -> np.ndarray:
    """The same frame moved along its x-y plane so that its origin lies below
    ``point_robot``: ``T_new_old @ T_robot_camera`` with ``T_new_old`` a translation by
    ``(-x, -y, 0)``."""
    shift = np.eye(4)
    shift[:2, 3] = -np.asarray(point_robot, dtype=np.float64)[:2]
    return shift @ np.asarray(T_robot_camera, dtype=np.float64)
