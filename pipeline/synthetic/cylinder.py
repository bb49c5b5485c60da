"""A vertical cylinder on the table seen once by a pinhole depth camera (frame ``R``, z up;
metres and radians).

Rays are intersected with the cylinder analytically, so the cloud holds only the visible
surface, with Gaussian range noise along each ray. ``u_cam`` is the horizontal unit vector
from the cylinder axis toward the camera (:func:`camera_direction`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.geometry.poses import look_at
from pipeline.sim.kinect import KINECT_V1_INTRINSICS
from pipeline.types import CameraIntrinsics, PointCloud


@dataclass(frozen=True)
class Cylinder:
    """A vertical cylinder standing on the table.

    Attributes:
        radius_m: radius (the paper's synthetic cylinder: 40 mm).
        height_m: height above its base.
        axis_xy_m: ``(x, y)`` of the axis in frame ``R``.
        base_z_m: z of its base (the table top).
    """

    radius_m: float = 0.04
    height_m: float = 0.10
    axis_xy_m: tuple[float, float] = (0.5, 0.0)
    base_z_m: float = 0.0

    @property
    def diameter_m(self) -> float:
        return 2.0 * self.radius_m

    @property
    def top_z_m(self) -> float:
        return self.base_z_m + self.height_m

    @property
    def centre_m(self) -> np.ndarray:
        """``(3,)`` centre of the cylinder (axis at mid-height)."""
        x, y = self.axis_xy_m
        return np.array([x, y, self.base_z_m + 0.5 * self.height_m])


@dataclass(frozen=True)
class Viewpoint:
    """Where the depth camera looks from, relative to the cylinder centre.

    Attributes:
        azimuth_rad: direction of the camera from the axis, about +z (0 = +x side).
        elevation_rad: camera height angle above the horizontal through the centre.
        distance_m: camera-to-centre distance.
        intrinsics: pinhole intrinsics (default :data:`pipeline.sim.kinect.KINECT_V1_INTRINSICS`).
    """

    azimuth_rad: float = np.pi
    elevation_rad: float = np.radians(30.0)
    distance_m: float = 0.8
    intrinsics: CameraIntrinsics = KINECT_V1_INTRINSICS


DEFAULT_CYLINDER = Cylinder()
DEFAULT_VIEWPOINT = Viewpoint()


@dataclass(frozen=True)
class CylinderView:
    """A single-view cloud of a cylinder with the camera that took it; ``on_cap`` flags the
    points on the top cap."""

    cloud: PointCloud
    T_robot_camera: np.ndarray
    intrinsics: CameraIntrinsics
    camera_position_m: np.ndarray
    on_cap: np.ndarray


def camera_direction(viewpoint: Viewpoint) -> np.ndarray:
    """``u_cam``: horizontal unit vector from the axis toward the camera, ``(3,)``."""
    return np.array([np.cos(viewpoint.azimuth_rad), np.sin(viewpoint.azimuth_rad), 0.0])


def _first_hit(
    origins: np.ndarray, directions: np.ndarray, cylinder: Cylinder
) -> tuple[np.ndarray, np.ndarray]:
    """Range to the first surface hit of each ray (inf for a miss), and whether it is the cap.

    Only the side wall and the top cap are surfaces (the base rests on the table).
    """
    axis = np.asarray(cylinder.axis_xy_m, dtype=np.float64)
    rel = origins[:, :2] - axis
    d_xy = directions[:, :2]
    a = np.einsum("ij,ij->i", d_xy, d_xy)
    b = np.einsum("ij,ij->i", rel, d_xy)
    c = np.einsum("ij,ij->i", rel, rel) - cylinder.radius_m**2
    disc = b * b - a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        t_side = (-b - np.sqrt(disc)) / a
    z_side = origins[:, 2] + t_side * directions[:, 2]
    side_ok = (
        (disc >= 0.0)
        & (t_side > 0.0)
        & (z_side >= cylinder.base_z_m)
        & (z_side <= cylinder.top_z_m)
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        t_cap = (cylinder.top_z_m - origins[:, 2]) / directions[:, 2]
    cap_xy = rel + t_cap[:, None] * d_xy
    cap_ok = (t_cap > 0.0) & (np.einsum("ij,ij->i", cap_xy, cap_xy) <= cylinder.radius_m**2)
    t_side = np.where(side_ok, t_side, np.inf)
    t_cap = np.where(cap_ok, t_cap, np.inf)
    return np.minimum(t_side, t_cap), t_cap < t_side


def render_cylinder(
    cylinder: Cylinder,
    viewpoint: Viewpoint,
    rng: np.random.Generator,
    *,
    range_noise_m: float = 0.0015,
    include_cap: bool = False,
) -> CylinderView:
    """Single-view point cloud of the cylinder's visible surface, frame ``R``.

    One ray per pixel of the intrinsics (only the window around the cylinder is traced);
    each hit is displaced along its ray by ``N(0, range_noise_m^2)``. The default noise,
    1.5 mm, is the Kinect axial model ``0.0012 + 0.0019 (z - 0.4)^2`` at 0.8 m.

    Args:
        include_cap: keep points on the top cap. Off by default: the diameter metric fits a
            circle to the projected cloud, and cap points would fill the disc.

    Raises:
        ValueError: the camera sees none of the cylinder.
    """
    centre = cylinder.centre_m
    T_robot_camera = look_at(
        centre, viewpoint.distance_m, viewpoint.elevation_rad, viewpoint.azimuth_rad
    )
    camera_m = T_robot_camera[:3, 3]
    rotation = T_robot_camera[:3, :3]
    intr = viewpoint.intrinsics

    x, y = cylinder.axis_xy_m
    corners = np.array(
        [
            [x + sx * cylinder.radius_m, y + sy * cylinder.radius_m, z]
            for sx in (-1, 1)
            for sy in (-1, 1)
            for z in (cylinder.base_z_m, cylinder.top_z_m)
        ]
    )
    corners_cam = (corners - camera_m) @ rotation
    if np.any(corners_cam[:, 2] <= 0.0):
        raise ValueError("the cylinder is not entirely in front of the camera")
    cols = intr.fx * corners_cam[:, 0] / corners_cam[:, 2] + intr.cx
    rows = intr.fy * corners_cam[:, 1] / corners_cam[:, 2] + intr.cy
    col_range = np.arange(
        max(int(np.floor(cols.min())), 0), min(int(np.ceil(cols.max())) + 1, intr.width)
    )
    row_range = np.arange(
        max(int(np.floor(rows.min())), 0), min(int(np.ceil(rows.max())) + 1, intr.height)
    )
    pixel_rows, pixel_cols = (
        g.reshape(-1) for g in np.meshgrid(row_range, col_range, indexing="ij")
    )
    rays_cam = np.column_stack(
        [
            (pixel_cols - intr.cx) / intr.fx,
            (pixel_rows - intr.cy) / intr.fy,
            np.ones(len(pixel_rows)),
        ]
    )
    rays = rays_cam @ rotation.T
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    ranges, on_cap = _first_hit(np.broadcast_to(camera_m, rays.shape), rays, cylinder)
    keep = np.isfinite(ranges) & (include_cap | ~on_cap)
    if not np.any(keep):
        raise ValueError("the camera sees none of the cylinder")
    noisy_ranges = ranges[keep] + rng.normal(0.0, range_noise_m, int(keep.sum()))
    points = camera_m + noisy_ranges[:, None] * rays[keep]
    pixels = np.column_stack([pixel_rows[keep], pixel_cols[keep]])
    return CylinderView(
        cloud=PointCloud(points=points, frame="robot", pixels=pixels),
        T_robot_camera=T_robot_camera,
        intrinsics=intr,
        camera_position_m=camera_m,
        on_cap=on_cap[keep],
    )


def scene_depth(
    cylinder: Cylinder, T_robot_camera: np.ndarray, intrinsics: CameraIntrinsics
) -> np.ndarray:
    """Noiseless depth image (m along the optical axis, ``(height, width)``) of the scene the
    cylinder stands in: the cylinder's side and top cap where a pixel's ray meets them, else
    the table (the plane ``z = base_z_m``), NaN where the ray never reaches the table (it
    points at or above the horizon). A camera over a tabletop sees the table around the
    object, so a model that puts matter beside the object contradicts the view."""
    rows, cols = np.indices((intrinsics.height, intrinsics.width)).reshape(2, -1)
    rays_cam = np.column_stack(
        [
            (cols - intrinsics.cx) / intrinsics.fx,
            (rows - intrinsics.cy) / intrinsics.fy,
            np.ones(len(rows)),
        ]
    )
    rays = rays_cam @ T_robot_camera[:3, :3].T  # unnormalised: range 1 is depth 1
    origin = T_robot_camera[:3, 3]
    depth, _ = _first_hit(np.broadcast_to(origin, rays.shape), rays, cylinder)
    with np.errstate(divide="ignore", invalid="ignore"):
        table = (cylinder.base_z_m - origin[2]) / rays[:, 2]
    table = np.where(table > 0.0, table, np.nan)
    depth = np.where(np.isfinite(depth), depth, table)
    return depth.reshape(intrinsics.height, intrinsics.width)


def cylinder_mesh(cylinder: Cylinder, segments: int = 128) -> tuple[np.ndarray, np.ndarray]:
    """Closed triangle mesh of the cylinder (side, top and bottom caps): vertices, faces.

    The side is a ``segments``-gon prism inscribed in the circle: its flat facets lie up to
    ``radius (1 - cos(pi / segments))`` inside the true surface (12 um at 128 segments).
    """
    angles = 2.0 * np.pi * np.arange(segments) / segments
    x, y = cylinder.axis_xy_m
    ring = np.column_stack(
        [x + cylinder.radius_m * np.cos(angles), y + cylinder.radius_m * np.sin(angles)]
    )
    bottom = np.column_stack([ring, np.full(segments, cylinder.base_z_m)])
    top = np.column_stack([ring, np.full(segments, cylinder.top_z_m)])
    centres = np.array([[x, y, cylinder.base_z_m], [x, y, cylinder.top_z_m]])
    vertices = np.vstack([bottom, top, centres])
    i = np.arange(segments)
    j = (i + 1) % segments
    bottom_centre, top_centre = 2 * segments, 2 * segments + 1
    faces = np.vstack(
        [
            np.column_stack([i, j, segments + j]),
            np.column_stack([i, segments + j, segments + i]),
            np.column_stack([np.full(segments, bottom_centre), j, i]),
            np.column_stack([np.full(segments, top_centre), segments + i, segments + j]),
        ]
    )
    return vertices, faces
