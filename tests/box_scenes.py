"""Depth images of axis-aligned boxes (tables, walls, cartons, blocks) for tests: a
ray caster and the capture files ``symfuse complete`` reads."""

from __future__ import annotations

import json

import numpy as np

from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT


def ray_cast(boxes, T_robot_camera: np.ndarray, stride: int = 2) -> np.ndarray:
    """Depth image (every ``stride``-th Kinect pixel, m, NaN = no hit) of axis-aligned
    boxes seen from ``T_robot_camera`` (slab test per box, nearest hit per ray)."""
    rows, cols = np.mgrid[0 : KINECT.height : stride, 0 : KINECT.width : stride]
    rays_camera = np.stack(
        [(cols - KINECT.cx) / KINECT.fx, (rows - KINECT.cy) / KINECT.fy, np.ones(rows.shape)],
        axis=-1,
    )
    rays = rays_camera @ T_robot_camera[:3, :3].T
    origin = T_robot_camera[:3, 3]
    depth = np.full(rows.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for low, high in boxes:
            t0 = (np.asarray(low) - origin) / rays
            t1 = (np.asarray(high) - origin) / rays
            near = np.minimum(t0, t1).max(axis=-1)
            far = np.maximum(t0, t1).min(axis=-1)
            hit = (near <= far) & (near > 0.0)
            depth = np.where(hit & (near < depth), near, depth)
    return np.where(np.isfinite(depth), depth, np.nan).astype(np.float32)


def points_camera(depth: np.ndarray, stride: int = 2) -> np.ndarray:
    rows, cols = np.nonzero(np.isfinite(depth))
    z = depth[rows, cols].astype(np.float64)
    u, v = cols * stride, rows * stride
    return np.column_stack([(u - KINECT.cx) * z / KINECT.fx, (v - KINECT.cy) * z / KINECT.fy, z])


def write_capture(folder, depth: np.ndarray, stride: int = 2):
    """``depth.npy`` and its camera.json (no robot frame: symfuse builds it on the support)."""
    k = KINECT
    camera = {
        "intrinsics": {
            "width": depth.shape[1],
            "height": depth.shape[0],
            "fx": k.fx / stride,
            "fy": k.fy / stride,
            "cx": k.cx / stride,
            "cy": k.cy / stride,
        }
    }
    (folder / "camera.json").write_text(json.dumps(camera))
    np.save(folder / "depth.npy", depth)
    return folder / "depth.npy"
