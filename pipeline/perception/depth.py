"""Pinhole geometry between a depth image and robot-frame points.

The camera optical frame ``C`` follows OpenCV (x right, y down, z forward); a pixel
``(row, col)`` has its centre at ``u = col``, ``v = row`` in the intrinsics' convention.
"""

from __future__ import annotations

import numpy as np

from pipeline.types import CameraIntrinsics


def backproject_depth(
    depth_m: np.ndarray, intrinsics: CameraIntrinsics, T_robot_camera: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Back-project every finite, positive depth pixel into the robot frame.

    Args:
        depth_m: ``(H, W)`` depth along the optical axis in metres, NaN where missing.
        intrinsics: pinhole intrinsics of the image.
        T_robot_camera: ``(4, 4)`` pose of the optical frame in the robot frame.

    Returns:
        ``points_robot`` ``(N, 3)`` metres and ``pixels`` ``(N, 2)`` int (row, col), in
        row-major pixel order.
    """
    depth = np.asarray(depth_m, dtype=np.float64)
    valid = np.isfinite(depth) & (depth > 0.0)
    rows, cols = np.nonzero(valid)
    z = depth[rows, cols]
    x = (cols - intrinsics.cx) * z / intrinsics.fx
    y = (rows - intrinsics.cy) * z / intrinsics.fy
    points_camera = np.column_stack([x, y, z])
    T = np.asarray(T_robot_camera, dtype=np.float64)
    points_robot = points_camera @ T[:3, :3].T + T[:3, 3]
    return points_robot, np.column_stack([rows, cols]).astype(np.int64)


def project_points(
    points_robot: np.ndarray, intrinsics: CameraIntrinsics, T_robot_camera: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project robot-frame points into the image.

    Args:
        points_robot: ``(..., 3)`` points in metres (any leading shape).
        intrinsics: the camera's pinhole intrinsics (px).
        T_robot_camera: the camera's pose in the robot frame (4x4, m).

    Returns:
        ``rows``, ``cols`` (int, nearest pixel; meaningless where ``depth <= 0``) and
        ``depth`` (metres along the optical axis), each of the leading shape. Callers check
        ``0 <= rows < H``, ``0 <= cols < W`` and ``depth > 0`` themselves.
    """
    T = np.asarray(T_robot_camera, dtype=np.float64)
    rotation_camera_robot = T[:3, :3].T
    points_camera = (points_robot - T[:3, 3]) @ rotation_camera_robot.T
    depth = points_camera[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intrinsics.fx * points_camera[..., 0] / depth + intrinsics.cx
        v = intrinsics.fy * points_camera[..., 1] / depth + intrinsics.cy
    finite = np.isfinite(u) & np.isfinite(v)
    cols = np.where(finite, np.rint(np.where(finite, u, 0.0)), -1).astype(np.int64)
    rows = np.where(finite, np.rint(np.where(finite, v, 0.0)), -1).astype(np.int64)
    return rows, cols, depth
