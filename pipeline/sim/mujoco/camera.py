"""Pinhole images of a MuJoCo scene by ray casting: one ``mj_multiRay`` from the camera
centre through every pixel centre. It needs no OpenGL context, so it runs on any machine
the ``mujoco`` wheel installs on (MuJoCo's own renderer needs EGL or OSMesa from the
system).

The rays see the table, the object's mesh (not its collision parts) and the hand. Depth
is exact along each pixel centre's ray; colour is each geom's colour shaded by the angle
between its surface and the ray (lit from the camera), as in the analytic test world.
"""

from __future__ import annotations

import mujoco
import numpy as np

from pipeline.sim.mujoco.scene import HAND_GROUP, OBJECT_VISUAL_GROUP, TABLE_GROUP
from pipeline.types import CameraIntrinsics

#: The geom groups the camera sees.
CAMERA_GROUPS = np.array(
    [group in (TABLE_GROUP, OBJECT_VISUAL_GROUP, HAND_GROUP) for group in range(6)],
    dtype=np.uint8,
)
#: Shade of a surface seen edge-on, and what a surface facing the camera adds to it.
AMBIENT = 0.35
DIFFUSE = 0.65


def pixel_rays(intrinsics: CameraIntrinsics) -> np.ndarray:
    """``(H W, 3)`` rays through the pixel centres, row-major, in the OpenCV optical
    frame, scaled to unit depth (z = 1), so a ray's length parameter at a hit is its
    depth along the optical axis."""
    rows, cols = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width]
    return np.stack(
        [
            (cols.ravel() - intrinsics.cx) / intrinsics.fx,
            (rows.ravel() - intrinsics.cy) / intrinsics.fy,
            np.ones(rows.size),
        ],
        axis=1,
    )


def ray_cast(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    intrinsics: CameraIntrinsics,
    T_robot_camera: np.ndarray,
    near_m: float,
    far_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rgb (H, W, 3) uint8, depth (H, W) float32 m, geom (H, W) int32)`` seen from
    ``T_robot_camera`` (OpenCV optical frame in R): depth along the optical axis, NaN and
    geom -1 where nothing lies between ``near_m`` and ``far_m``."""
    T = np.asarray(T_robot_camera, dtype=np.float64)
    rays = pixel_rays(intrinsics)
    directions = np.ascontiguousarray(rays @ T[:3, :3].T)
    count = len(directions)
    geom = np.empty(count, dtype=np.int32)
    depth = np.empty(count)
    normals = np.empty(3 * count)
    # The cutoff is a distance along the (longer than unit) rays: far enough for the
    # image's corners, the far plane applied to depth below.
    cutoff = far_m * float(np.linalg.norm(rays, axis=1).max())
    mujoco.mj_multiRay(
        model,
        data,
        np.ascontiguousarray(T[:3, 3]),
        directions.ravel(),
        CAMERA_GROUPS,
        1,
        -1,
        geom,
        depth,
        normals,
        count,
        cutoff,
    )
    seen = (geom >= 0) & (depth >= near_m) & (depth <= far_m)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    facing = np.abs(np.sum(normals.reshape(-1, 3) * unit, axis=1))
    colour = model.geom_rgba[np.maximum(geom, 0), :3] * 255.0
    colour *= (AMBIENT + DIFFUSE * facing)[:, None]
    colour[~seen] = 0.0
    shape = (intrinsics.height, intrinsics.width)
    return (
        np.clip(colour, 0.0, 255.0).astype(np.uint8).reshape(*shape, 3),
        np.where(seen, depth, np.nan).astype(np.float32).reshape(shape),
        np.where(seen, geom, -1).astype(np.int32).reshape(shape),
    )
