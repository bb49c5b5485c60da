"""Synthetic cylinder scenes for the paper's synthetic studies (docs/method.md §7).

A vertical cylinder stands on the table (frame ``R``, z up). A pinhole depth camera sees it
once; rays are intersected with the cylinder analytically, so the cloud holds only the
visible surface, with Gaussian range noise along each ray. A hand (a parallel jaw with two
flat 6x14 pads, or three flat 6x14 pads 120 degrees apart) touches the *true* surface; a
taxel reports contact when the curved surface lies within a threshold of it along its
normal. The contacts are then moved by a true bias (object motion / calibration error), so
they live in the biased frame, exactly what the estimator is asked to undo.

Conventions used throughout (angles in radians, lengths in metres):

* ``u_cam``: the horizontal unit vector from the cylinder axis toward the camera. The true
  symmetry plane contains the axis and is perpendicular to ``u_cam`` (it mirrors the visible
  front onto the hidden back); its normal is ``u_cam``.
* Initial symmetry error ``(theta, r)``: the normal is rotated by ``theta`` about the axis
  (counter-clockwise seen from above) and the plane then shifted by ``r`` along the rotated
  normal; ``r > 0`` moves it toward the camera, so the mirrored back overlaps the front.
  At ``theta = 90 deg`` the plane contains the view direction and mirrors the front onto
  itself (paper Fig. 7).
* Tactile angle ``phi``: the grasp's angle about the axis relative to the view. Pad ``k``
  touches the surface at azimuth ``psi_front + phi + k * 2 pi / n_pads`` where
  ``psi_front`` is the azimuth of ``u_cam``. Parallel jaw at ``phi = 0`` is the front-and-back
  grasp; three fingers at ``phi = 0`` have the thumb on the front and two fingers at the
  back, at ``phi = 180 deg`` two fingers on the front.
* Bias: ``f_b(p) = R_z(yaw) (p - c) + c + t`` with the pivot ``c`` the centroid of the
  generated cloud (the estimator's convention), ``t`` horizontal.

All randomness comes from the ``np.random.Generator`` passed in.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from .kinect import KINECT_V1_INTRINSICS
from .poses import look_at, rotation_z
from .types import (
    Bias,
    CameraIntrinsics,
    Contacts,
    DepthObservation,
    EstimationProblem,
    PointCloud,
    SymmetryInit,
    SymmetryPlane,
)

GripperKind = Literal["parallel", "three_finger"]

#: Pad ids per gripper, in the order of their contact azimuths (see module docstring).
PAD_NAMES: dict[str, tuple[str, ...]] = {
    "parallel": ("left", "right"),
    "three_finger": ("thumb_proximal", "f1_proximal", "f2_proximal"),
}


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
        intrinsics: pinhole intrinsics (default Kinect v1, 640x480, f = 575.8 px).
    """

    azimuth_rad: float = np.pi
    elevation_rad: float = np.radians(30.0)
    distance_m: float = 0.8
    intrinsics: CameraIntrinsics = KINECT_V1_INTRINSICS


@dataclass(frozen=True)
class PadGeometry:
    """A flat tactile pad: ``rows`` along the finger (vertical), ``cols`` across it.

    Defaults: Weiss DSA 9205-style, 6 x 14 taxels at 3.4 mm (the Weiss datasheet).
    """

    rows: int = 14
    cols: int = 6
    pitch_m: float = 0.0034


@dataclass(frozen=True)
class TouchSettings:
    """How the pads meet the surface.

    Attributes:
        grasp_height_m: pad-centre height above the cylinder base; None puts the pad's top
            row 5 mm below the cylinder top (a top grasp covering the upper part).
        press_depth_m: how far the flat pad is pushed into the surface (compliant pad).
        contact_threshold_m: a taxel reports contact when the surface along its normal is
            closer than this (the flat pad touches the curved surface only near its centre
            line: at 3.4 mm pitch and 40 mm radius, the outer columns lie 0.33 mm and 0.92 mm
            off the surface).
        position_noise_m: std of Gaussian noise added to each contact position.
    """

    grasp_height_m: float | None = None
    press_depth_m: float = 0.0
    contact_threshold_m: float = 0.5e-3
    position_noise_m: float = 0.0


DEFAULT_CYLINDER = Cylinder()
DEFAULT_VIEWPOINT = Viewpoint()
DEFAULT_PAD = PadGeometry()
DEFAULT_TOUCH = TouchSettings()


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


def contact_azimuths(
    gripper: GripperKind, tactile_angle_rad: float, viewpoint: Viewpoint
) -> np.ndarray:
    """Azimuths (about the axis, frame ``R``) where each pad of the hand touches, radians."""
    n_pads = len(PAD_NAMES[gripper])
    return viewpoint.azimuth_rad + tactile_angle_rad + 2.0 * np.pi * np.arange(n_pads) / n_pads


def touch_pads(
    cylinder: Cylinder,
    azimuths_rad: np.ndarray,
    pad_names: tuple[str, ...],
    rng: np.random.Generator,
    *,
    pad: PadGeometry = DEFAULT_PAD,
    touch: TouchSettings = DEFAULT_TOUCH,
) -> Contacts:
    """Flat pads placed tangentially on the cylinder at the given azimuths; taxels in contact.

    Pad ``k`` is a vertical plane at distance ``radius - press_depth`` from the axis, facing
    the axis at ``azimuths_rad[k]``; taxel normals point into the object (toward the axis).
    Row ``i`` (along the finger, top to bottom) and column ``j`` give the row-major index
    ``i * cols + j``. A taxel is in contact when the ray along its normal enters the side wall
    within ``contact_threshold_m`` (or the taxel is already inside it), at a height on the
    cylinder.
    """
    grasp_height = (
        cylinder.height_m - 0.005 - 0.5 * (pad.rows - 1) * pad.pitch_m
        if touch.grasp_height_m is None
        else touch.grasp_height_m
    )
    row_offsets = (0.5 * (pad.rows - 1) - np.arange(pad.rows)) * pad.pitch_m
    col_offsets = (np.arange(pad.cols) - 0.5 * (pad.cols - 1)) * pad.pitch_m
    rows, cols = (g.reshape(-1) for g in np.meshgrid(row_offsets, col_offsets, indexing="ij"))
    indices = np.arange(pad.rows * pad.cols)
    axis_xy = np.asarray(cylinder.axis_xy_m, dtype=np.float64)
    positions, normals, names, taxel_indices = [], [], [], []
    for name, azimuth in zip(pad_names, azimuths_rad, strict=True):
        outward = np.array([np.cos(azimuth), np.sin(azimuth)])
        tangent = np.array([-outward[1], outward[0]])
        centre_xy = axis_xy + (cylinder.radius_m - touch.press_depth_m) * outward
        taxel_xy = centre_xy + cols[:, None] * tangent
        taxel_z = cylinder.base_z_m + grasp_height + rows
        # Entry of the ray taxel_xy - s * outward into the circle: solve |q - s u - a| = R.
        rel = taxel_xy - axis_xy
        b = rel @ outward
        disc = b * b - (np.einsum("ij,ij->i", rel, rel) - cylinder.radius_m**2)
        with np.errstate(invalid="ignore"):
            entry = b - np.sqrt(disc)
            exit_ = b + np.sqrt(disc)
        touching = (
            (disc >= 0.0)
            & (entry <= touch.contact_threshold_m)
            & (exit_ >= 0.0)
            & (taxel_z >= cylinder.base_z_m)
            & (taxel_z <= cylinder.top_z_m)
        )
        count = int(touching.sum())
        positions.append(np.column_stack([taxel_xy[touching], taxel_z[touching]]))
        normals.append(np.tile([-outward[0], -outward[1], 0.0], (count, 1)))
        names.extend([name] * count)
        taxel_indices.append(indices[touching])
    positions_m = np.concatenate(positions)
    if touch.position_noise_m > 0.0:
        positions_m = positions_m + rng.normal(0.0, touch.position_noise_m, positions_m.shape)
    return Contacts(
        positions=positions_m,
        normals=np.concatenate(normals),
        pads=np.array(names, dtype=str),
        taxel_indices=np.concatenate(taxel_indices),
    )


def move_contacts(contacts: Contacts, bias: Bias) -> Contacts:
    """Contacts seen through a bias: positions by ``f_b``, normals rotated by its yaw."""
    return Contacts(
        positions=bias.apply(contacts.positions),
        normals=contacts.normals @ rotation_z(bias.yaw_rad).T,
        pads=contacts.pads,
        taxel_indices=contacts.taxel_indices,
    )


def perturbed_plane(
    true_plane: SymmetryPlane, axis_xy_m: np.ndarray, theta_rad: float, r_m: float
) -> SymmetryPlane:
    """The true plane rotated by ``theta_rad`` about the vertical axis through ``axis_xy_m``,
    then shifted by ``r_m`` along its (rotated) normal."""
    theta = true_plane.theta_rad + theta_rad
    normal_xy = np.array([np.cos(theta), np.sin(theta)])
    axis_offset = true_plane.offset_m - true_plane.normal[:2] @ np.asarray(axis_xy_m)
    return SymmetryPlane(
        theta_rad=float(theta),
        offset_m=float(normal_xy @ np.asarray(axis_xy_m) + axis_offset + r_m),
    )


@dataclass(frozen=True)
class SyntheticCase:
    """One synthetic trial: what the estimator gets and the truth to score it against.

    Attributes:
        cloud: the visible cylinder surface, frame ``R`` (with pixels).
        contacts: taxels in contact, in the biased frame.
        true_plane: the symmetry plane completing the cylinder (normal toward the camera).
        init_plane: ``true_plane`` with the initial error ``(theta, r)`` applied.
        true_bias: the bias the contacts were moved by (pivot = cloud centroid).
        cylinder, viewpoint: the scene.
        T_robot_camera: the camera pose.
        gripper: ``"parallel"`` or ``"three_finger"``.
        tactile_angle_rad: the grasp's angle relative to the view.
    """

    cloud: PointCloud
    contacts: Contacts
    true_plane: SymmetryPlane
    init_plane: SymmetryPlane
    true_bias: Bias
    cylinder: Cylinder
    viewpoint: Viewpoint
    T_robot_camera: np.ndarray
    gripper: GripperKind
    tactile_angle_rad: float

    @property
    def pivot_m(self) -> np.ndarray:
        """The bias pivot: centroid of the cloud."""
        return self.true_bias.pivot_m

    @property
    def view(self) -> DepthObservation:
        """The depth image the cloud came from: each cloud pixel holds its point's depth
        along the optical axis; every other pixel is unknown (NaN: the scene has no table
        or background, so rays that miss the cylinder return nothing)."""
        intrinsics = self.viewpoint.intrinsics
        depth = np.full((intrinsics.height, intrinsics.width), np.nan, dtype=np.float32)
        camera = (self.cloud.points - self.T_robot_camera[:3, 3]) @ self.T_robot_camera[:3, :3]
        rows, cols = self.cloud.pixels.T
        depth[rows, cols] = camera[:, 2]
        return DepthObservation(
            depth_m=depth,
            rgb=np.zeros((*depth.shape, 3), dtype=np.uint8),
            intrinsics=intrinsics,
            T_robot_camera=self.T_robot_camera,
        )

    @property
    def problem(self) -> EstimationProblem:
        """The estimation problem: cloud, init plane with zero bias, one grasp, the view."""
        init = SymmetryInit(plane=self.init_plane, bias=Bias(pivot_m=self.pivot_m))
        return EstimationProblem(
            cloud=self.cloud, init=init, grasps=(self.contacts,), view=self.view
        )


def make_case(
    rng: np.random.Generator,
    *,
    gripper: GripperKind = "parallel",
    tactile_angle_rad: float = 0.0,
    theta_error_rad: float = 0.0,
    r_error_m: float = 0.0,
    bias_magnitude_m: float = 0.0,
    bias_direction_rad: float | None = None,
    bias_yaw_rad: float = 0.0,
    cylinder: Cylinder = DEFAULT_CYLINDER,
    viewpoint: Viewpoint = DEFAULT_VIEWPOINT,
    range_noise_m: float = 0.0015,
    pad: PadGeometry = DEFAULT_PAD,
    touch: TouchSettings = DEFAULT_TOUCH,
) -> SyntheticCase:
    """Generate one synthetic trial (see the module docstring for every convention).

    Args:
        rng: source of all randomness (cloud noise, bias direction when not given, taxel
            noise).
        gripper: ``"parallel"`` (two pads) or ``"three_finger"`` (three pads, 120 deg apart).
        tactile_angle_rad: grasp angle relative to the view.
        theta_error_rad, r_error_m: initial symmetry error.
        bias_magnitude_m: length of the horizontal bias translation.
        bias_direction_rad: its direction about +z; None draws it uniformly from ``rng``.
        bias_yaw_rad: bias rotation about the vertical through the pivot.
    """
    if gripper not in PAD_NAMES:
        raise ValueError(f"unknown gripper {gripper!r} (known: {', '.join(PAD_NAMES)})")
    view = render_cylinder(cylinder, viewpoint, rng, range_noise_m=range_noise_m)
    u_cam = camera_direction(viewpoint)
    axis_xy = np.asarray(cylinder.axis_xy_m, dtype=np.float64)
    true_plane = SymmetryPlane(
        theta_rad=float(viewpoint.azimuth_rad), offset_m=float(u_cam[:2] @ axis_xy)
    )
    init_plane = perturbed_plane(true_plane, axis_xy, theta_error_rad, r_error_m)
    direction = rng.uniform(0.0, 2.0 * np.pi) if bias_direction_rad is None else bias_direction_rad
    true_bias = Bias(
        yaw_rad=bias_yaw_rad,
        translation_m=bias_magnitude_m * np.array([np.cos(direction), np.sin(direction), 0.0]),
        pivot_m=view.cloud.points.mean(axis=0),
    )
    azimuths = contact_azimuths(gripper, tactile_angle_rad, viewpoint)
    touched = touch_pads(cylinder, azimuths, PAD_NAMES[gripper], rng, pad=pad, touch=touch)
    return SyntheticCase(
        cloud=view.cloud,
        contacts=move_contacts(touched, true_bias),
        true_plane=true_plane,
        init_plane=init_plane,
        true_bias=true_bias,
        cylinder=cylinder,
        viewpoint=viewpoint,
        T_robot_camera=view.T_robot_camera,
        gripper=gripper,
        tactile_angle_rad=tactile_angle_rad,
    )


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
