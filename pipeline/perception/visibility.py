"""Visibility constraints for mirror-plane hypotheses (VC initialisation, paper section 4.2).

A depth image divides space along every pixel's ray into *free* space (in front of the
measured surface), the surface itself and *occluded* space behind it. A mirrored object
point that projects onto a pixel with a measurement and lies closer to the camera than
that measurement by more than a tolerance sits in known free space: the hypothesis that
produced it is violated there. Table and background pixels count as free space too; NaN
pixels, points outside the image and points behind the camera are unknown, never a
violation.

Hypotheses form an ``O x D`` grid: normal angles ``theta`` within ``+-max_angle_rad`` of a
seed normal (the PCA minor axis: the plane contains the major axis ``e_a`` and z) and
offsets ``r`` from the centroid ``c`` along each normal, so ``m_r = n(theta) . c + r``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.types import CameraIntrinsics


@dataclass(frozen=True)
class PlaneGrid:
    """An ``O x D`` grid of vertical plane hypotheses ``{p : n(theta) . p = offset}``.

    Attributes:
        angle_steps_rad: ``(O,)`` rotation of each normal relative to the seed normal.
        offset_steps_m: ``(D,)`` offset of each plane from the centroid along its normal.
        theta_rad: ``(O, D)`` absolute normal angle about +z.
        offset_m: ``(O, D)`` plane offset ``m_r`` in the robot frame.
    """

    angle_steps_rad: np.ndarray
    offset_steps_m: np.ndarray
    theta_rad: np.ndarray
    offset_m: np.ndarray


def plane_grid(
    seed_theta_rad: float,
    centroid_m: np.ndarray,
    *,
    max_angle_rad: float,
    orientations: int,
    max_offset_m: float,
    offsets: int,
) -> PlaneGrid:
    """Evenly spaced hypotheses: ``orientations`` angles in ``seed +- max_angle_rad`` and
    ``offsets`` offsets in ``+- max_offset_m`` from the centroid (both inclusive; a single
    step sits at the seed / the centroid)."""
    steps_theta = (
        np.linspace(-max_angle_rad, max_angle_rad, orientations)
        if orientations > 1
        else np.zeros(1)
    )
    steps_r = np.linspace(-max_offset_m, max_offset_m, offsets) if offsets > 1 else np.zeros(1)
    theta = seed_theta_rad + steps_theta
    centre_along_normal = np.cos(theta) * centroid_m[0] + np.sin(theta) * centroid_m[1]
    return PlaneGrid(
        angle_steps_rad=steps_theta,
        offset_steps_m=steps_r,
        theta_rad=np.repeat(theta[:, None], len(steps_r), axis=1),
        offset_m=centre_along_normal[:, None] + steps_r[None, :],
    )


def visibility_violations(
    points_robot: np.ndarray,
    theta_rad: np.ndarray,
    offset_m: np.ndarray,
    depth_m: np.ndarray,
    intrinsics: CameraIntrinsics,
    T_robot_camera: np.ndarray,
    *,
    tolerance_m: float = 0.01,
    chunk: int = 16,
) -> tuple[np.ndarray, np.ndarray]:
    """Count the mirrored points in known free space, for every hypothesis at once.

    Mirroring is affine, so in camera coordinates ``q' = q - 2 (n . p - m_r) R^T n`` with
    ``q`` the original point's camera coordinates: one ``(H, N)`` array per coordinate,
    processed in chunks of ``chunk`` hypotheses to stay in cache.

    Args:
        points_robot: ``(N, 3)`` object points in the robot frame, metres.
        theta_rad: ``(H,)`` (or any shape equal to ``offset_m``'s) plane normal angles.
        offset_m: the planes' offsets, metres.
        depth_m: ``(rows, cols)`` measured depth, NaN where missing.
        intrinsics: the camera the image was taken with.
        T_robot_camera: its pose (as believed).
        tolerance_m: how far in front of the measured surface a point may be before it
            counts as a violation (sensor noise and quantisation).
        chunk: hypotheses per vectorised block.

    Returns:
        ``violations`` (int, shape of ``theta_rad``): number of violating points, and
        ``depth_sum_m`` (float, same shape): summed distance in front of the surface
        (beyond the tolerance) over the violating points, a tie-breaker.
    """
    points = np.asarray(points_robot, dtype=np.float64)
    shape = np.shape(theta_rad)
    theta = np.asarray(theta_rad, dtype=np.float64).reshape(-1)
    offset = np.asarray(offset_m, dtype=np.float64).reshape(-1)
    T = np.asarray(T_robot_camera, dtype=np.float64)
    rotation_camera_robot = T[:3, :3].T
    q = (points - T[:3, 3]) @ rotation_camera_robot.T
    # Visit points in image order: mirroring is affine, so neighbours stay neighbours and
    # the depth look-ups below stay cache-friendly whatever order the cloud came in.
    with np.errstate(divide="ignore", invalid="ignore"):
        order = np.lexsort((q[:, 0] / q[:, 2], np.round(q[:, 1] / q[:, 2] * intrinsics.fy)))
    points, q = points[order], q[order]
    normals = np.column_stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)])
    normals_camera = normals @ rotation_camera_robot.T
    limit = _free_space_limits(depth_m, tolerance_m)
    qx, qy, qz = (q[:, k].astype(np.float32) for k in range(3))

    violations = np.zeros(len(theta), dtype=np.int64)
    depth_sum = np.zeros(len(theta))
    for start in range(0, len(theta), chunk):
        block = slice(start, start + chunk)
        twice_signed = (2.0 * (normals[block, :2] @ points[:, :2].T - offset[block, None])).astype(
            np.float32
        )
        nx, ny, nz = (normals_camera[block, k, None].astype(np.float32) for k in range(3))
        in_front = _in_front(
            qx - twice_signed * nx,
            qy - twice_signed * ny,
            qz - twice_signed * nz,
            limit,
            intrinsics,
        )
        violations[block] = np.count_nonzero(in_front > 0.0, axis=1)
        depth_sum[block] = np.maximum(in_front, 0.0).sum(axis=1, dtype=np.float64)
    return violations.reshape(shape), depth_sum.reshape(shape)


def free_space_depths(
    points_robot: np.ndarray,
    depth_m: np.ndarray,
    intrinsics: CameraIntrinsics,
    T_robot_camera: np.ndarray,
) -> np.ndarray:
    """How far each point lies in front of the surface the camera measured on its ray.

    The same test as :func:`visibility_violations` for one set of points, without a
    tolerance: a point at depth ``z`` (optical axis, frame C) projecting onto a pixel that
    measured ``d`` gets ``d - z``; positive values are in known free space.

    Args:
        points_robot: ``(N, 3)`` points in the robot frame, metres.
        depth_m, intrinsics, T_robot_camera: the camera's image and pose (as believed).

    Returns:
        ``(N,)`` distance in front of the measured surface (m); ``-inf`` where unknown (NaN
        pixel, outside the image, behind the camera).
    """
    T = np.asarray(T_robot_camera, dtype=np.float64)
    q = (np.asarray(points_robot, dtype=np.float64) - T[:3, 3]) @ T[:3, :3]
    limit = _free_space_limits(depth_m, 0.0)
    qx, qy, qz = (q[:, k].astype(np.float32) for k in range(3))
    return _in_front(qx, qy, qz, limit, intrinsics).astype(np.float64)


def _free_space_limits(depth_m: np.ndarray, tolerance_m: float) -> np.ndarray:
    """Per pixel the measured depth minus the tolerance, ``-inf`` where unknown, row-major,
    with one extra ``-inf`` entry for points outside the image (float32 is ample at these
    ranges)."""
    limit = np.asarray(depth_m, dtype=np.float32).reshape(-1) - np.float32(tolerance_m)
    return np.append(np.where(np.isfinite(limit), limit, -np.inf), -np.inf).astype(np.float32)


def _in_front(
    qx: np.ndarray,
    qy: np.ndarray,
    qz: np.ndarray,
    limit: np.ndarray,
    intrinsics: CameraIntrinsics,
) -> np.ndarray:
    """``limit[pixel] - z`` of camera-frame points (float32 arrays of any equal shape)."""
    height, width = intrinsics.height, intrinsics.width
    fx, fy = np.float32(intrinsics.fx), np.float32(intrinsics.fy)
    cx, cy = np.float32(intrinsics.cx), np.float32(intrinsics.cy)
    in_view = qz > 1e-3
    inverse_z = np.reciprocal(np.where(in_view, qz, np.float32(1.0)))
    # Nearest pixel, shifted by one so truncation toward zero equals floor wherever the
    # result can be inside the image (valid shifted indices are 1..size).
    col = (fx * qx * inverse_z + (cx + 1.5)).astype(np.int32)
    row = (fy * qy * inverse_z + (cy + 1.5)).astype(np.int32)
    inside = in_view & (col >= 1) & (col <= width) & (row >= 1) & (row <= height)
    index = np.where(inside, row * width + col - (width + 1), height * width)
    return limit[index] - qz
