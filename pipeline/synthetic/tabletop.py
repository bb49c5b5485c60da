"""Analytic depth images of simple objects on a table, for tests and benchmarks.

An object is a union of axis-aligned convex primitives (boxes, elliptic cylinders) in its
own frame (z up, base on ``z = 0``). It stands on the infinite table plane
``z = table_height_m`` of the robot frame at a planar pose ``(x, y, yaw)``. Rays of a
pinhole camera are intersected with every primitive and the table exactly, which gives
noise-free depth along the optical axis; optional Gaussian axial noise follows the Kinect
model of Nguyen et al. 2012 (``sigma_z = 0.0012 + 0.0019 (z - 0.4)^2`` m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.geometry.poses import look_at, rotation_z
from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT
from pipeline.sim.kinect import axial_sigma_m
from pipeline.types import CameraIntrinsics, DepthObservation


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in the object frame: ``centre_m`` (3,) and ``half_extents_m`` (3,)."""

    centre_m: tuple[float, float, float]
    half_extents_m: tuple[float, float, float]


@dataclass(frozen=True)
class EllipticCylinder:
    """Vertical elliptic cylinder in the object frame: axis through ``centre_xy_m``,
    semi-axes ``semi_axes_m`` along x and y, between heights ``z_min_m`` and ``z_max_m``."""

    centre_xy_m: tuple[float, float]
    semi_axes_m: tuple[float, float]
    z_min_m: float
    z_max_m: float


Primitive = Box | EllipticCylinder


@dataclass(frozen=True)
class SyntheticObject:
    """A union of primitives with its true vertical mirror planes through the origin.

    Attributes:
        name: label for reports.
        primitives: the convex parts, object frame.
        symmetry_normals_xy: unit normals (object frame) of the true symmetry planes, all
            through the object origin.
        rotational: True when every vertical plane through the z axis is a symmetry plane.
    """

    name: str
    primitives: tuple[Primitive, ...]
    symmetry_normals_xy: tuple[tuple[float, float], ...]
    rotational: bool = False

    @property
    def height_m(self) -> float:
        tops = [
            p.centre_m[2] + p.half_extents_m[2] if isinstance(p, Box) else p.z_max_m
            for p in self.primitives
        ]
        return float(max(tops))


def box_object(thickness_m: float, length_m: float, height_m: float) -> SyntheticObject:
    """A box, ``thickness_m`` along x, ``length_m`` along y (e.g. a CD drive on its side)."""
    half = (thickness_m / 2, length_m / 2, height_m / 2)
    return SyntheticObject("box", (Box((0.0, 0.0, height_m / 2), half),), ((1.0, 0.0), (0.0, 1.0)))


def cylinder_object(radius_m: float, height_m: float) -> SyntheticObject:
    """An upright circular cylinder (e.g. a salt container)."""
    return SyntheticObject(
        "cylinder",
        (EllipticCylinder((0.0, 0.0), (radius_m, radius_m), 0.0, height_m),),
        ((1.0, 0.0),),
        rotational=True,
    )


def spray_bottle_object() -> SyntheticObject:
    """A spray-bottle-like shape: an elliptic body (80 x 52 mm, 180 mm tall), a narrower
    neck and a trigger head reaching out along +x. Its only mirror plane is ``y = 0``."""
    return SyntheticObject(
        "spray-bottle",
        (
            EllipticCylinder((0.0, 0.0), (0.040, 0.026), 0.0, 0.180),
            EllipticCylinder((0.0, 0.0), (0.016, 0.016), 0.180, 0.215),
            Box((0.022, 0.0, 0.232), (0.042, 0.013, 0.020)),
        ),
        ((0.0, 1.0),),
    )


def _box_interval(origin, direction, box: Box):
    centre = np.asarray(box.centre_m)
    half = np.asarray(box.half_extents_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (centre - half - origin) / direction
        t2 = (centre + half - origin) / direction
    t_near = np.nanmax(np.minimum(t1, t2), axis=-1)
    t_far = np.nanmin(np.maximum(t1, t2), axis=-1)
    return t_near, t_far


def _cylinder_interval(origin, direction, cylinder: EllipticCylinder):
    a, b = cylinder.semi_axes_m
    ox = (origin[..., 0] - cylinder.centre_xy_m[0]) / a
    oy = (origin[..., 1] - cylinder.centre_xy_m[1]) / b
    dx, dy, dz = direction[..., 0] / a, direction[..., 1] / b, direction[..., 2]
    qa = dx * dx + dy * dy
    qb = 2.0 * (ox * dx + oy * dy)
    qc = ox * ox + oy * oy - 1.0
    disc = qb * qb - 4.0 * qa * qc
    root = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
    with np.errstate(divide="ignore", invalid="ignore"):
        side_near = (-qb - root) / (2.0 * qa)
        side_far = (-qb + root) / (2.0 * qa)
        z1 = (cylinder.z_min_m - origin[..., 2]) / dz
        z2 = (cylinder.z_max_m - origin[..., 2]) / dz
    t_near = np.fmax(side_near, np.minimum(z1, z2))
    t_far = np.fmin(side_far, np.maximum(z1, z2))
    return np.where(np.isfinite(root), t_near, np.inf), np.where(np.isfinite(root), t_far, -np.inf)


def render_depth(
    obj: SyntheticObject,
    pose_xy_yaw: tuple[float, float, float],
    table_height_m: float,
    intrinsics: CameraIntrinsics,
    T_robot_camera: np.ndarray,
    *,
    max_range_m: float = 4.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact depth image (metres along the optical axis, NaN beyond ``max_range_m`` or where
    nothing is hit) and the ``(H, W)`` bool mask of pixels that see the object."""
    rows, cols = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width]
    rays_camera = np.stack(
        [
            (cols - intrinsics.cx) / intrinsics.fx,
            (rows - intrinsics.cy) / intrinsics.fy,
            np.ones(rows.shape),
        ],
        axis=-1,
    )
    T = np.asarray(T_robot_camera, dtype=np.float64)
    rays_robot = rays_camera @ T[:3, :3].T  # t along these is depth along the optical axis
    origin_robot = T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_table = (table_height_m - origin_robot[2]) / rays_robot[..., 2]
    t_table = np.where(t_table > 0.0, t_table, np.inf)

    x, y, yaw = pose_xy_yaw
    rotation_object_robot = rotation_z(yaw).T
    origin_object = rotation_object_robot @ (origin_robot - np.array([x, y, table_height_m]))
    rays_object = rays_robot @ rotation_object_robot.T
    t_object = np.full(rows.shape, np.inf)
    for primitive in obj.primitives:
        interval = _box_interval if isinstance(primitive, Box) else _cylinder_interval
        t_near, t_far = interval(origin_object, rays_object, primitive)
        hit = (t_near <= t_far) & (t_near > 0.0)
        t_object = np.where(hit, np.minimum(t_object, t_near), t_object)
    mask = t_object < t_table
    depth = np.minimum(t_object, t_table)
    depth = np.where(depth <= max_range_m, depth, np.nan).astype(np.float32)
    return depth, mask & np.isfinite(depth)


def kinect_noise(depth_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Add Gaussian axial noise ``sigma_z = 0.0012 + 0.0019 (z - 0.4)^2`` (metres)."""
    sigma = axial_sigma_m(depth_m)
    noisy = depth_m + rng.standard_normal(depth_m.shape) * sigma
    return noisy.astype(np.float32)


def synthetic_observation(
    obj: SyntheticObject,
    pose_xy_yaw: tuple[float, float, float],
    *,
    table_height_m: float = 0.0,
    distance_m: float = 1.0,
    elevation_rad: float = np.deg2rad(45.0),
    azimuth_rad: float = np.pi,
    intrinsics: CameraIntrinsics = KINECT,
    rng: np.random.Generator | None = None,
) -> DepthObservation:
    """A Kinect-like observation of ``obj`` looked at from ``distance_m`` at its mid-height.

    With ``rng`` the depth gets Kinect axial noise; without, it is exact.
    """
    target = np.array([pose_xy_yaw[0], pose_xy_yaw[1], table_height_m + obj.height_m / 2])
    T_robot_camera = look_at(target, distance_m, elevation_rad, azimuth_rad)
    depth, mask = render_depth(obj, pose_xy_yaw, table_height_m, intrinsics, T_robot_camera)
    if rng is not None:
        depth = kinect_noise(depth, rng)
    return DepthObservation(
        depth_m=depth,
        rgb=np.zeros((intrinsics.height, intrinsics.width, 3), dtype=np.uint8),
        intrinsics=intrinsics,
        T_robot_camera=T_robot_camera,
        table_height_m=table_height_m,
        object_mask=mask,
    )


def sample_surface(obj: SyntheticObject, spacing_m: float = 0.002) -> np.ndarray:
    """Points ``(N, 3)`` on the surfaces of the object's primitives (object frame), about
    ``spacing_m`` apart. Parts of a primitive's surface inside another are included; they
    never change a support (extreme) point of the union, which is what tests use."""
    parts = []
    for p in obj.primitives:
        if isinstance(p, Box):
            centre, half = np.asarray(p.centre_m), np.asarray(p.half_extents_m)
            for axis in range(3):
                others = [i for i in range(3) if i != axis]
                u = np.arange(-half[others[0]], half[others[0]] + 1e-9, spacing_m)
                v = np.arange(-half[others[1]], half[others[1]] + 1e-9, spacing_m)
                uu, vv = np.meshgrid(u, v, indexing="ij")
                for sign in (-1.0, 1.0):
                    face = np.zeros((uu.size, 3))
                    face[:, axis] = sign * half[axis]
                    face[:, others[0]] = uu.ravel()
                    face[:, others[1]] = vv.ravel()
                    parts.append(face + centre)
        else:
            a, b = p.semi_axes_m
            count = max(8, int(np.ceil(2 * np.pi * max(a, b) / spacing_m)))
            angle = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
            z = np.arange(p.z_min_m, p.z_max_m + 1e-9, spacing_m)
            aa, zz = np.meshgrid(angle, z, indexing="ij")
            parts.append(
                np.column_stack(
                    [
                        p.centre_xy_m[0] + a * np.cos(aa.ravel()),
                        p.centre_xy_m[1] + b * np.sin(aa.ravel()),
                        zz.ravel(),
                    ]
                )
            )
            gx, gy = np.meshgrid(
                np.arange(-a, a + 1e-9, spacing_m), np.arange(-b, b + 1e-9, spacing_m)
            )
            inside = (gx / a) ** 2 + (gy / b) ** 2 <= 1.0
            for z_cap in (p.z_min_m, p.z_max_m):
                parts.append(
                    np.column_stack(
                        [
                            p.centre_xy_m[0] + gx[inside],
                            p.centre_xy_m[1] + gy[inside],
                            np.full(inside.sum(), z_cap),
                        ]
                    )
                )
    return np.concatenate(parts)


def place(points_object: np.ndarray, pose_xy_yaw, table_height_m: float) -> np.ndarray:
    """Object-frame points ``(N, 3)`` to the robot frame for an object at ``pose_xy_yaw``."""
    x, y, yaw = pose_xy_yaw
    return points_object @ rotation_z(yaw).T + np.array([x, y, table_height_m])
