"""Synthetic cylinder trials for the paper's synthetic studies (docs/method.md §7).

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

from pipeline.geometry.poses import rotation_z
from pipeline.sim.depth_noise import kinect_v1_dropouts
from pipeline.synthetic.cylinder import (
    DEFAULT_CYLINDER,
    DEFAULT_VIEWPOINT,
    Cylinder,
    Viewpoint,
    camera_direction,
    render_cylinder,
    scene_depth,
)
from pipeline.types import (
    Bias,
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


DEFAULT_PAD = PadGeometry()
DEFAULT_TOUCH = TouchSettings()


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
    def bias_to_pads_rad(self) -> float:
        """The bias translation's direction relative to the pads, in
        ``[-pi / n_pads, pi / n_pads)``: its angle about +z from the nearest pad's contact
        azimuth (0: the bias points from the axis toward a pad, so that pad's taxels lie
        inside the model Stage 0 gives), the pads' spacing folded away. 0 for no bias."""
        translation = self.true_bias.translation_m
        if not np.any(translation[:2]):
            return 0.0
        spacing = 2.0 * np.pi / len(PAD_NAMES[self.gripper])
        pad = contact_azimuths(self.gripper, self.tactile_angle_rad, self.viewpoint)[0]
        angle = np.arctan2(translation[1], translation[0]) - pad
        return float((angle + 0.5 * spacing) % spacing - 0.5 * spacing)

    @property
    def view(self) -> DepthObservation:
        """The depth image the cloud came from, as a Kinect v1 reports it: each cloud pixel
        holds its point's depth along the optical axis; every other pixel the noiseless scene
        around it, the top cap and the table the cylinder stands on
        (:func:`~.cylinder.scene_depth`); NaN (no return) where the sensor returns nothing
        (:func:`pipeline.sim.depth_noise.kinect_v1_dropouts`: both sides of the outline,
        the projector's shadow, the side seen at grazing incidence). The cloud keeps its
        points there (the paper's synthetic cloud).

        Without the table, a model that mirrors the hidden side out beside the cylinder
        contradicted nothing the camera saw and passed the self-diagnosis 100 mm and more
        off; with the table but a return on every pixel up to the outline, the mirrored
        front of a right model, whose noise turns across the rays at the silhouette, put
        points a pixel outside it, in front of the table, where a real sensor returns
        nothing."""
        intrinsics = self.viewpoint.intrinsics
        scene = scene_depth(self.cylinder, self.T_robot_camera, intrinsics)
        depth = scene.astype(np.float32)
        camera = (self.cloud.points - self.T_robot_camera[:3, 3]) @ self.T_robot_camera[:3, :3]
        rows, cols = self.cloud.pixels.T
        depth[rows, cols] = camera[:, 2]
        depth[kinect_v1_dropouts(scene, intrinsics)] = np.nan
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
    # Thirteen parameters: each knob of a synthetic case, keyword-only with its default.
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
