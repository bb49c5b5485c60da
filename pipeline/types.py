"""Data types exchanged between the pipeline's stages.

Every type that crosses a stage boundary lives in this one module (hence its length), so
that a plugin author finds the whole vocabulary of the contracts in one place.

Conventions used everywhere in symfuse:

* Units are SI: metres, radians, seconds. Reports may print mm and degrees.
* The **robot frame** ``R`` is the base frame everything is estimated in: z points up, the
  table top is the plane ``z = table_height_m`` with normal +z.
* The **camera optical frame** ``C`` follows OpenCV: x right, y down, z along the optical
  axis. ``T_robot_camera`` maps homogeneous camera-frame points into the robot frame.
* Homogeneous transforms are 4x4 ``float64`` arrays named ``T_<to>_<from>``.
* Point arrays are ``(N, 3) float64``.

The estimator's parameter order, used by every covariance in these types, is
``(b_theta, b_x, b_y, b_z, m_r, m_theta)`` (docs/method.md §1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal, Protocol

import numpy as np

from pipeline.geometry.poses import rotation_z

BIAS_PLANE_PARAMETERS = ("b_theta", "b_x", "b_y", "b_z", "m_r", "m_theta")
"""Parameter names of the 6x6 bias-and-plane covariance, in order."""
GENERAL_PLANE_PARAMETERS = (*BIAS_PLANE_PARAMETERS, "m_phi")
"""Parameter names of the 7x7 covariance when the estimator fuses a leaning plane: its
normal's azimuth ``m_theta`` and elevation ``m_phi`` (docs/symmetry.md)."""

EstimateStatus = Literal[
    "initial", "converged", "max_iterations", "no_correspondence", "diverged", "inconsistent"
]
"""A stage's status: ``initial`` (Stage 0), ``converged`` (and consistent with the
evidence), ``max_iterations``, ``no_correspondence``, ``diverged``, ``inconsistent``."""
PlanStatus = Literal["ok", "refused"]
"""A grasp plan's status: ``ok``, or ``refused`` with the planner's reason."""


def _as_points(array: np.ndarray, what: str) -> np.ndarray:
    points = np.asarray(array, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{what} must have shape (N, 3), got {points.shape}")
    return points


def _as_transform(array: np.ndarray, what: str) -> np.ndarray:
    transform = np.asarray(array, dtype=np.float64)
    if transform.shape != (4, 4):
        raise ValueError(f"{what} must be a 4x4 homogeneous transform, got {transform.shape}")
    return transform


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of a depth (or colour) image, in pixels.

    ``(cx, cy)`` is the principal point measured from the centre of the top-left pixel,
    columns to the right and rows down.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 calibration matrix ``K``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class DepthObservation:
    """One depth (and colour) image of the scene, as a sensor source delivers it.

    Attributes:
        depth_m: ``(H, W) float32`` metric depth along the optical axis (z in frame ``C``),
            ``NaN`` where the sensor returned nothing (out of range, shadow, edge).
        rgb: ``(H, W, 3) uint8`` colour image registered to the depth image.
        intrinsics: the depth camera's intrinsics.
        T_robot_camera: the camera pose the pipeline *believes* (it may carry a calibration
            error relative to the truth, which the estimator's bias absorbs).
        table_height_m: z of the table top in frame ``R`` when the source knows it, else None.
        object_mask: ``(H, W) bool`` ground-truth object pixels (simulation only), else None.
        calibration_error: ``(4, 4)`` the rigid motion the believed camera pose applies to
            every point the camera measures, ``T_believed T_true^-1`` in frame ``R``
            (simulation only, for scoring the estimated bias), else None.
        frame_from_support: True when the source had no robot frame and built one on the
            support plane (:mod:`pipeline.perception.support`): its origin is then a
            convention that ``symfuse complete`` moves below the segmented object.
    """

    depth_m: np.ndarray
    rgb: np.ndarray
    intrinsics: CameraIntrinsics
    T_robot_camera: np.ndarray
    table_height_m: float | None = None
    object_mask: np.ndarray | None = None
    frame_from_support: bool = False
    calibration_error: np.ndarray | None = None

    def __post_init__(self) -> None:
        shape = (self.intrinsics.height, self.intrinsics.width)
        if self.depth_m.shape != shape:
            raise ValueError(f"depth image shape {self.depth_m.shape} != intrinsics {shape}")
        _as_transform(self.T_robot_camera, "T_robot_camera")
        if self.calibration_error is not None:
            _as_transform(self.calibration_error, "calibration_error")


@dataclass(frozen=True)
class PointCloud:
    """A set of 3-D points in a named frame.

    Attributes:
        points: ``(N, 3) float64`` coordinates in metres.
        frame: name of the frame the points are expressed in (``"robot"`` for every cloud
            that crosses a stage boundary).
        pixels: optional ``(N, 2) int`` (row, column) of the depth pixel each point came
            from; lets visibility reasoning go back to the image.
        viewpoint_m: optional ``(3,)`` position of the sensor's optical centre in
            ``frame`` (m); tells which side of the object the camera saw.
    """

    points: np.ndarray
    frame: str = "robot"
    pixels: np.ndarray | None = None
    viewpoint_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", _as_points(self.points, "PointCloud.points"))
        if self.pixels is not None and len(self.pixels) != len(self.points):
            raise ValueError("PointCloud.pixels must have one row per point")
        if self.viewpoint_m is not None:
            viewpoint = np.asarray(self.viewpoint_m, dtype=np.float64)
            if viewpoint.shape != (3,) or not np.all(np.isfinite(viewpoint)):
                raise ValueError("PointCloud.viewpoint_m must be a finite (3,) position")
            object.__setattr__(self, "viewpoint_m", viewpoint)

    def __len__(self) -> int:
        return len(self.points)


@dataclass(frozen=True)
class SymmetryPlane:
    """A vertical mirror plane ``{p : n . p = offset_m}`` in frame ``R``.

    The unit normal is horizontal, ``n = (cos theta_rad, sin theta_rad, 0)`` (docs/method.md
    §1: ``m_theta`` is the normal's angle about +z, ``m_r`` the offset).
    """

    theta_rad: float
    offset_m: float

    @property
    def normal(self) -> np.ndarray:
        """The unit normal ``(3,)`` in frame ``R``."""
        return np.array([np.cos(self.theta_rad), np.sin(self.theta_rad), 0.0])

    @classmethod
    def from_normal(cls, normal_xy: np.ndarray, offset_m: float) -> SymmetryPlane:
        """Build from any non-zero horizontal normal ``(nx, ny)``; it is normalised and the
        offset scaled with it, so ``{nx x + ny y = offset_m}`` is the same set of points."""
        nx, ny = (float(v) for v in normal_xy)
        length = float(np.hypot(nx, ny))
        if not np.isfinite(length) or length == 0.0:
            raise ValueError("symmetry plane normal must be a finite, non-zero (nx, ny)")
        return cls(theta_rad=float(np.arctan2(ny, nx)), offset_m=float(offset_m) / length)

    def mirror(self, points: np.ndarray) -> np.ndarray:
        """Reflect ``(N, 3)`` points across the plane: ``p - 2 (n.p - offset) n``."""
        n = self.normal
        return points - 2.0 * (points @ n - self.offset_m)[:, None] * n[None, :]


#: The kinds of symmetry: the paper's mirror plane perpendicular to the table, a mirror plane
#: of any orientation, and a rotation axis (a body of revolution).
SymmetryKind = Literal["vertical-plane", "plane", "axis"]
SYMMETRY_KINDS: tuple[SymmetryKind, ...] = ("vertical-plane", "plane", "axis")

#: The parameters each kind of :class:`Symmetry` is estimated in, in covariance order: the
#: vertical plane's offset and normal angle about +z (docs/method.md §1); a general plane's
#: offset, its normal's azimuth about +z and elevation above the table; an axis' direction
#: (azimuth, elevation) and the two coordinates of its points across it, along
#: :meth:`Symmetry.across_axes`.
SYMMETRY_PARAMETERS: dict[str, tuple[str, ...]] = {
    "vertical-plane": ("m_r", "m_theta"),
    "plane": ("m_r", "m_azimuth", "m_elevation"),
    "axis": ("a_azimuth", "a_elevation", "a_u", "a_v"),
}


@dataclass(frozen=True)
class Symmetry:
    """One symmetry of an object, in the frame its holder names (frame ``R`` at a stage
    boundary, the object frame in a catalogue entry or a ``symmetry.json``).

    Attributes:
        kind: ``"vertical-plane"`` / ``"plane"``: the mirror plane through ``point_m`` with
            unit normal ``direction`` (horizontal for ``"vertical-plane"``); ``"axis"``: the
            object is a body of revolution about the line through ``point_m`` along
            ``direction``.
        direction: ``(3,)`` unit normal of the plane, or unit direction of the axis. Its
            sign carries no meaning.
        point_m: ``(3,)`` a point of the plane or of the axis (m).
        covariance: covariance of :attr:`parameters`, in that order (m, rad), or None when
            its source does not give one.
        residual_m: how far the object is from being symmetric about it (the mesh search's
            mean distance of the moved surface from the surface, m); NaN when not measured.
    """

    kind: SymmetryKind
    direction: np.ndarray
    point_m: np.ndarray
    covariance: np.ndarray | None = None
    residual_m: float = math.nan

    def __post_init__(self) -> None:
        if self.kind not in SYMMETRY_KINDS:
            raise ValueError(f"symmetry kind must be one of {', '.join(SYMMETRY_KINDS)}")
        direction = np.asarray(self.direction, dtype=np.float64).reshape(3)
        length = float(np.linalg.norm(direction))
        if not np.isfinite(length) or length == 0.0:
            raise ValueError("a symmetry's direction must be a finite, non-zero (3,) vector")
        point = np.asarray(self.point_m, dtype=np.float64).reshape(3)
        if not np.isfinite(point).all():
            raise ValueError("a symmetry's point must be a finite (3,) position")
        object.__setattr__(self, "direction", direction / length)
        object.__setattr__(self, "point_m", point)
        if self.covariance is not None:
            size = len(SYMMETRY_PARAMETERS[self.kind])
            covariance = np.asarray(self.covariance, dtype=np.float64)
            if covariance.shape != (size, size):
                raise ValueError(f"a {self.kind} covariance must be {size}x{size}")
            object.__setattr__(self, "covariance", covariance)

    @classmethod
    def from_plane(cls, plane: SymmetryPlane, covariance: np.ndarray | None = None) -> Symmetry:
        """The paper's vertical plane as a ``"vertical-plane"`` symmetry; ``covariance`` is
        that of ``(m_r, m_theta)``."""
        normal = plane.normal
        return cls("vertical-plane", normal, normal * plane.offset_m, covariance)

    @property
    def is_plane(self) -> bool:
        return self.kind != "axis"

    @property
    def offset_m(self) -> float:
        """A plane's offset ``d`` in ``{p : n . p = d}`` (m)."""
        return float(self.direction @ self.point_m)

    @property
    def parameters(self) -> tuple[str, ...]:
        """The names of the kind's parameters (:data:`SYMMETRY_PARAMETERS`)."""
        return SYMMETRY_PARAMETERS[self.kind]

    @property
    def values(self) -> np.ndarray:
        """The parameters' values, in the order of :attr:`parameters` (m, rad)."""
        d = self.direction
        if self.kind == "vertical-plane":
            return np.array([self.offset_m, np.arctan2(d[1], d[0])])
        # The sign is free: the one with the upper-half direction (or, level, the one with a
        # non-negative azimuth in (-pi/2, pi/2]) names the same plane or axis.
        if d[2] < 0.0 or (d[2] == 0.0 and (d[0] < 0.0 or (d[0] == 0.0 and d[1] < 0.0))):
            d = -d
        azimuth, elevation = np.arctan2(d[1], d[0]), np.arcsin(np.clip(d[2], -1.0, 1.0))
        if self.kind == "plane":
            return np.array([float(d @ self.point_m), azimuth, elevation])
        u, v = self.across_axes()
        return np.array([azimuth, elevation, u @ self.point_m, v @ self.point_m])

    def across_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Two unit vectors ``(u, v)`` completing ``direction`` to a right-handed basis:
        ``u`` horizontal (along +x when the direction is vertical)."""
        d = self.direction
        u = np.cross([0.0, 0.0, 1.0], d)
        u = np.array([1.0, 0.0, 0.0]) if np.linalg.norm(u) < 1e-9 else u / np.linalg.norm(u)
        return u, np.cross(d, u)

    def transformed(self, T: np.ndarray) -> Symmetry:
        """The same symmetry after the rigid motion ``T`` (4x4), without a covariance (its
        parameters are frame-dependent); a moved vertical plane is a general one unless the
        motion keeps it vertical."""
        T = np.asarray(T, dtype=np.float64)
        direction = T[:3, :3] @ self.direction
        kind = self.kind
        if kind == "vertical-plane" and abs(direction[2]) > 1e-9:
            kind = "plane"
        return Symmetry(kind, direction, T[:3, :3] @ self.point_m + T[:3, 3], None, self.residual_m)

    def apply(self, points: np.ndarray, angle_rad: float = math.pi) -> np.ndarray:
        """Mirror ``(N, 3)`` points across the plane, or turn them by ``angle_rad`` about the
        axis (right-handed about ``direction``)."""
        points = np.asarray(points, dtype=np.float64)
        d, relative = self.direction, points - self.point_m
        if self.is_plane:
            return points - 2.0 * (relative @ d)[:, None] * d[None, :]
        along = (relative @ d)[:, None] * d[None, :]
        across = relative - along
        turned = math.cos(angle_rad) * across + math.sin(angle_rad) * np.cross(d, across)
        return self.point_m + along + turned


@dataclass(frozen=True)
class Bias:
    """Rigid planar motion between the camera's view and the hand's frame (docs/method.md §1).

    ``f_b(p) = R_z(yaw_rad) (p - pivot_m) + pivot_m + translation_m``. It absorbs both the
    object's motion during the grasp and the camera-to-robot calibration error. The pivot is
    fixed during estimation (symfuse uses the centroid of the segmented cloud).
    """

    yaw_rad: float = 0.0
    translation_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    pivot_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "translation_m", np.asarray(self.translation_m, float).reshape(3))
        object.__setattr__(self, "pivot_m", np.asarray(self.pivot_m, float).reshape(3))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Move ``(N, 3)`` robot-frame points by the bias."""
        rotation = rotation_z(self.yaw_rad)
        return (points - self.pivot_m) @ rotation.T + self.pivot_m + self.translation_m

    @property
    def transform(self) -> np.ndarray:
        """The bias as a 4x4 rigid motion of robot-frame points."""
        rotation = rotation_z(self.yaw_rad)
        matrix = np.eye(4)
        matrix[:3, :3] = rotation
        matrix[:3, 3] = self.pivot_m + self.translation_m - rotation @ self.pivot_m
        return matrix


@dataclass(frozen=True)
class PadLayout:
    """Geometry of one tactile pad: a ``rows x cols`` grid of taxels at ``pitch_m``.

    Attributes:
        name: pad id as it appears in :class:`Contacts` (e.g. ``"left"``, ``"f1_distal"``).
        link: name of the URDF link the pad is fixed to.
        rows, cols: taxel grid size (rows run along the finger, cols across it).
        pitch_m: centre-to-centre taxel distance.
    """

    name: str
    link: str
    rows: int
    cols: int
    pitch_m: float


@dataclass(frozen=True)
class ClosingPad:
    """A tactile pad that closes on the object horizontally, as the next-grasp scoring
    predicts its touch (:func:`pipeline.planning.next_grasp.pad_approaches`). Palm frame (the hand
    frame of :attr:`GraspPlan.T_robot_hand`): z along the approach, x the closing
    direction.

    Attributes:
        pad: the pad's name (one of :attr:`GripperSpec.pads`).
        base_m: ``(x, y)`` in the palm's xy plane (m) of the line the pad closes along:
            its finger's base (the palm axis for a parallel gripper's jaws).
        facing: ``(x, y)`` unit direction the pad faces and closes along at spread 0.
        spread_sign: how the facing turns with the plan's spread
            (:attr:`GraspPlan.spread_rad`): by ``+spread``, ``-spread`` or not at all
            (``1``, ``-1``, ``0``).
        curved_rows: the rows nearest the fingertip that lie on a cylinder curving away
            from the object (0: a flat pad).
        curve_radius_m: that cylinder's radius (m; unused for a flat pad).
    """

    pad: str
    base_m: tuple[float, float]
    facing: tuple[float, float]
    spread_sign: int = 0
    curved_rows: int = 0
    curve_radius_m: float = 0.0

    @staticmethod
    def jaws(front: str, back: str) -> tuple[ClosingPad, ClosingPad]:
        """A parallel gripper's flat pads, closing on the palm axis: ``front`` along +x,
        ``back`` along -x."""
        return ClosingPad(front, (0.0, 0.0), (1.0, 0.0)), ClosingPad(back, (0.0, 0.0), (-1.0, 0.0))


@dataclass(frozen=True)
class PadMount:
    """Where a tactile pad sits on its finger and how large it is, read from the hand's URDF
    (:func:`pipeline.io.hand_urdf.read_hand_geometry`). Palm frame (the URDF's root link:
    z along the approach toward the fingertips), every joint at 0, metres.

    Attributes:
        pad: the pad's name, its link's without the ``_pad`` suffix (``"left"``,
            ``"f1_distal"``).
        link: the pad's URDF link; its frame is at the pad surface's centre, z along the
            outward normal, x along the rows toward the fingertip.
        finger: the finger carrying it (see :class:`HandGeometry`).
        centre_m: ``(x, y, z)`` the pad surface's centre.
        normal: ``(x, y, z)`` its outward unit normal (toward the grasped object).
        length_m, width_m: the pad's collision shapes' extent along its rows and across.
        centre_to_fingertip_m: how far its finger reaches beyond the pad's centre along
            the rows (the farthest collision shape of the pad's link, the link carrying
            it and every link below).
        recess_m: how far the link carrying the pad stays behind the pad's surface.
    """

    pad: str
    link: str
    finger: str
    centre_m: tuple[float, float, float]
    normal: tuple[float, float, float]
    length_m: float
    width_m: float
    centre_to_fingertip_m: float
    recess_m: float


@dataclass(frozen=True)
class Housing:
    """The palm's collision shapes (the URDF's root link), palm frame, metres: how deep
    they reach along z, their half extents along x (the closing direction) and y, and the
    radius about the palm axis they stay within (a cylinder's own radius)."""

    depth_m: float
    half_length_m: float
    half_width_m: float
    radius_m: float


@dataclass(frozen=True)
class BendingFinger:
    """A finger of a turn-and-bend hand (the SDH-2's): a base joint about the palm's z at
    ``base_m`` (or fixed), a knuckle, then two bending joints about the link's y, the
    proximal link and the distal link carrying one pad each. Link frames: z along the
    finger toward the tip, x toward the side the pads face. Metres and radians.

    Attributes:
        name: the finger's name (its links' prefix).
        base_m: ``(x, y)`` the base joint's origin in the palm's xy plane.
        base_depth_m: the base joint's origin below the palm origin (along z).
        spread_sign: how the finger's facing turns with the base joint: ``1`` or ``-1``
            (its axis along +z or -z), ``0`` for a fixed base.
        facing: ``(x, y)`` unit direction its pads face at base angle 0.
        knuckle_length_m: base joint to the first bending joint.
        knuckle_radius_m: radius of the knuckle's cylinder.
        proximal_length_m: first to second bending joint.
        distal_length_m: second bending joint to the fingertip.
        half_width_m: half the proximal link's width across the facing.
        proximal_back_m: the proximal link's back (negative: behind its axis).
        proximal_pad_offset_m: the proximal pad's surface in front of the link's axis.
        distal_back_m: the distal link's back behind its axis (negative).
        distal_pad_offset_m: the distal pad's surface in front of the link's axis.
        distal_pad_centre_m: the distal pad's centre along the link from its joint.
        bend_limit_rad: the bending joints' range, ``[-limit, limit]``.
    """

    name: str
    base_m: tuple[float, float]
    base_depth_m: float
    spread_sign: int
    facing: tuple[float, float]
    knuckle_length_m: float
    knuckle_radius_m: float
    proximal_length_m: float
    distal_length_m: float
    half_width_m: float
    proximal_back_m: float
    proximal_pad_offset_m: float
    distal_back_m: float
    distal_pad_offset_m: float
    distal_pad_centre_m: float
    bend_limit_rad: float


@dataclass(frozen=True)
class HandGeometry:
    """A hand's shape as planners and the next-grasp scoring use it, read once from its URDF
    (:func:`pipeline.io.hand_urdf.read_hand_geometry`; the naming convention is there and
    in docs/hands.md). Palm frame, every joint at 0, metres.

    Attributes:
        urdf: the file it was read from.
        fingers: the fingers' names, one per chain of links hanging from the palm (a link's
            finger is its name's prefix before the first ``_``).
        pads: every pad (links named ``<name>_pad``), in the URDF's order.
        housing: the palm's collision shapes.
        fingertip_depth_m: the deepest collision shape below the palm origin (along z).
        jaw_half_width_m: for a parallel gripper (fingers on prismatic joints), half the
            jaws' widest extent across the closing direction (y); 0 otherwise.
        jaw_travel_m: for a parallel gripper, the pad surfaces' distance at joints 0 plus
            every jaw's stroke: the widest opening between the pads; 0 otherwise.
        jaw_closed_m: for a parallel gripper, the pad surfaces' distance at joints 0.
        jaws: a parallel gripper's prismatic joints, in :attr:`fingers` order.
        jaw_speed_m_s: the slowest of their velocity limits (m/s; 0 without jaws).
        bending: the fingers of a turn-and-bend hand (:class:`BendingFinger`).
        closing: each finger's pad nearest its fingertip, closing from the finger's base
            joint along the pad's normal (flat: the taxel layout, not the URDF, says which
            rows curve; :attr:`GripperSpec.closing` has them).
    """

    urdf: str
    fingers: tuple[str, ...]
    pads: tuple[PadMount, ...]
    housing: Housing
    fingertip_depth_m: float
    jaw_half_width_m: float = 0.0
    jaw_travel_m: float = 0.0
    jaw_closed_m: float = 0.0
    jaws: tuple[str, ...] = ()
    jaw_speed_m_s: float = 0.0
    bending: tuple[BendingFinger, ...] = ()
    closing: tuple[ClosingPad, ...] = ()

    def pad(self, name: str) -> PadMount:
        """The pad ``name``.

        Raises:
            KeyError: the hand has no such pad.
        """
        for mount in self.pads:
            if mount.pad == name:
                return mount
        raise KeyError(f"the hand of {self.urdf} has no pad '{name}'")


@dataclass(frozen=True)
class GripperSpec:
    """What grasp planners need to know about a hand.

    Attributes:
        name: ``"pg70"`` or ``"sdh"`` (or a user hand's name).
        fingers: number of fingers (2 for a parallel gripper).
        max_aperture_m: widest opening between the pad surfaces.
        pads: the tactile pads.
        finger_length_m: reach of the fingers below the palm, used to place top grasps.
        closing: the pads that close on the object and how (:class:`ClosingPad`): what
            the next-grasp scoring predicts each candidate's touch from. A hand without
            them has no predicted touch, so an information-scored later grasp cannot
            prefer its candidates.
        geometry: the hand's shape read from its URDF (:class:`HandGeometry`): where the
            pads sit, the fingers' links, the housing. Planners place the hand with it;
            None for a hand described by these numbers alone.
    """

    name: str
    fingers: int
    max_aperture_m: float
    pads: tuple[PadLayout, ...]
    finger_length_m: float
    closing: tuple[ClosingPad, ...] = ()
    geometry: HandGeometry | None = None


@dataclass(frozen=True)
class GraspCandidate:
    """A top grasp a planner considered (:mod:`pipeline.planning.grasp_candidates`).

    Attributes:
        closing_angle_deg: closing direction's angle from the proposed plane's normal.
        height_m: height of the pad centres above the table the planner assumed.
        spread_deg: SDH base rotation (0 for a parallel gripper).
        width_m: the object's width along the closing direction there (m).
        contact_coverage: predicted contact quality of each finger's pad (front/thumb
            first): the fraction of its taxels touching the surface times the squared
            cosine of the surface's inclination to the pad.
        tipping_ratio: contact height over the object's half-footprint along the closing
            direction.
        score: in [0, 1], higher is better; 0 when infeasible.
        feasible: whether the hand can execute it.
        reason: why it is infeasible, else empty.
    """

    closing_angle_deg: float
    height_m: float
    spread_deg: float
    width_m: float
    contact_coverage: tuple[float, ...]
    tipping_ratio: float
    score: float
    feasible: bool
    reason: str = ""


@dataclass(frozen=True)
class GraspPlan:
    """A planned top grasp, in frame ``R``.

    Attributes:
        gripper: name of the hand the plan is for.
        status: ``"ok"`` or ``"refused"`` (then ``reason`` says why and nothing is executed).
        T_robot_hand: hand (palm) pose at the grasp; its z axis points down the approach
            direction (toward the table), its x axis is the closing direction.
        pregrasp_height_m: how far above ``T_robot_hand`` the hand starts its descent.
        opening_m: aperture to open to before the descent.
        closing_direction: ``(3,)`` horizontal unit vector along which the fingers close,
            equal to ``T_robot_hand``'s x axis, pointing from the *front* finger (the jaw or
            the SDH thumb on the camera's side) to the back one, so that the front pad
            touches the visible surface and the back pad the hidden one
            (``pipeline.api.planning.front_to_back`` orients a direction so).
        predicted_contacts: ``(K, 3)`` points on the cloud where the pads are expected to
            touch first (used by PS initialisation for the initial bias).
        spread_rad: SDH base rotation (0 for a parallel gripper).
        reason: why a plan was refused, else empty.
        score: how good the planner deems the grasp, in [0, 1] (higher is better; the
            same scale for every planner, so that ``trial.gripper = "auto"`` can compare
            hands); NaN when the planner does not score. The built-in planners score
            *contact x alignment x stability*: the smallest predicted pad contact quality
            over the fingers (0 to 1: how squarely each pad meets a side), ``(1 + |cos a|)
            / 2`` for a closing direction ``a`` from the plane normal, and ``1 / (1 + w h /
            f)`` for the contact height ``h`` above the table over the object's
            half-footprint ``f`` along the closing direction (``w``: ``tipping_weight``,
            0.2 by default); ``pipeline.api.planning.CandidatePlanner`` computes it.
        candidates: the grasps the planner considered, best first (empty when it
            considered only one).
    """

    gripper: str
    status: PlanStatus
    T_robot_hand: np.ndarray
    pregrasp_height_m: float
    opening_m: float
    closing_direction: np.ndarray
    predicted_contacts: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    spread_rad: float = 0.0
    reason: str = ""
    score: float = math.nan
    candidates: tuple[GraspCandidate, ...] = ()


@dataclass(frozen=True)
class Contacts:
    """The taxels in contact after one grasp, in frame ``R`` (forward kinematics of the
    hand's final configuration).

    Attributes:
        positions: ``(M, 3)`` taxel centres, metres.
        normals: ``(M, 3)`` unit normals pointing out of the pad, into the object.
        pads: ``(M,)`` pad id of each taxel (str).
        taxel_indices: ``(M,)`` index of the taxel within its pad, row-major.
    """

    positions: np.ndarray
    normals: np.ndarray
    pads: np.ndarray
    taxel_indices: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "positions", _as_points(self.positions, "Contacts.positions"))
        object.__setattr__(self, "normals", _as_points(self.normals, "Contacts.normals"))
        object.__setattr__(self, "pads", np.asarray(self.pads, dtype=str).reshape(-1))
        object.__setattr__(
            self, "taxel_indices", np.asarray(self.taxel_indices, dtype=np.int64).reshape(-1)
        )
        m = len(self.positions)
        if not (len(self.normals) == len(self.pads) == len(self.taxel_indices) == m):
            raise ValueError("Contacts fields must all have one row per taxel")

    def __len__(self) -> int:
        return len(self.positions)

    def select(self, keep: np.ndarray) -> Contacts:
        """The taxels where the boolean mask ``keep`` (``(M,)``) is true."""
        return Contacts(
            self.positions[keep], self.normals[keep], self.pads[keep], self.taxel_indices[keep]
        )


@dataclass(frozen=True)
class SymmetryHypothesis:
    """One scored plane hypothesis (VC initialisation keeps all of them, ranked)."""

    plane: SymmetryPlane
    score: float
    violations: int


@dataclass(frozen=True)
class SymmetryInit:
    """What a symmetry initialiser hands the estimator: the Stage 0 state.

    Attributes:
        plane: initial symmetry plane.
        bias: initial bias (zero unless the initialiser saw contacts, as PS does).
        hypotheses: ranked hypotheses, best first (empty when not applicable).
        status: ``"ok"`` or ``"rejected"`` (every hypothesis was hopeless).
        reason: explanation for a rejection, else empty.
        symmetry: the symmetry the initialiser found when it looks beyond the vertical
            plane (:mod:`pipeline.symmetry`); None: the ``"vertical-plane"`` ``plane``.
            A ``"plane"`` here (a leaning one) is what the built-in estimators fuse, in
            the seven-parameter state; for an ``"axis"`` they fuse ``plane`` (through the
            axis), and the axis' own completion is :func:`pipeline.symmetry.kinds.complete`'s.
        kind_scores: the evidence each kind of symmetry had when the initialiser chose
            between them (kind -> penalised violation score, lower is better); empty when
            it did not choose.
    """

    plane: SymmetryPlane
    bias: Bias
    hypotheses: tuple[SymmetryHypothesis, ...] = ()
    status: Literal["ok", "rejected"] = "ok"
    reason: str = ""
    symmetry: Symmetry | None = None
    kind_scores: dict[str, float] = field(default_factory=dict)

    @property
    def kind(self) -> SymmetryKind:
        """The kind of symmetry the initialiser proposes (``"vertical-plane"`` unless
        :attr:`symmetry` says otherwise)."""
        return "vertical-plane" if self.symmetry is None else self.symmetry.kind

    @property
    def proposed(self) -> Symmetry:
        """The proposed symmetry: :attr:`symmetry`, or :attr:`plane` as a vertical plane."""
        return Symmetry.from_plane(self.plane) if self.symmetry is None else self.symmetry


@dataclass(frozen=True)
class IterationState:
    """The estimate after one iteration of an iterative estimator, kept for inspection
    (``result.json``'s ``trace``, the Rerun recording's iteration timeline).

    Attributes:
        grasp: index of the grasp being fused (0-based, in the order the grasps happened).
        plane, bias: the state after the iteration.
        active_taxels: taxels with some correspondence weight in the iteration.
        active_points: points inside some taxel's gate in the iteration.
    """

    grasp: int
    plane: SymmetryPlane
    bias: Bias
    active_taxels: int
    active_points: int


@dataclass(frozen=True)
class Consistency:
    """How well a stage's completed model explains the evidence (self-diagnosis, see
    :mod:`pipeline.estimation.consistency`).

    Attributes:
        checks: the checks that ran: ``"taxels"`` (always, when there were contacts) and
            ``"free_space"`` (only when the problem carried the camera's depth image), and
            ``"plane_turn"`` (a fused stage of a leaning plane).
        taxel_rms_m: RMS distance of the taxels in contact from the model's surface (m),
            NaN without taxels.
        nis: pad-averaged normalised innovation squared of those residuals against the
            taxel noise and the model surface's std (about 1 when consistent).
        nis_threshold: its bound at the configured false-alarm probability.
        free_space_violations: model points lying in space the camera saw empty, None when
            that check did not run.
        free_space_limit: the most such points allowed, None when that check did not run.
        consistent: every check that ran passed.
        reason: which check failed and by how much; empty when consistent.
        after_view_nis: a fused stage's bias against the after-views (the sum of their
            normalised innovations, :func:`pipeline.estimation.consistency.after_view_test`),
            None for Stage 0 (whose bias is no estimate) and without an after-view. It
            does not enter ``consistent``: the selection weighs it (docs/method.md §9).
        after_view_threshold: its bound at the configured false-alarm probability, None
            with it.
        plane_turn_deg: a fused leaning plane's turn from the initialiser's normal (deg,
            :func:`pipeline.estimation.consistency.plane_turn_test`), None for a vertical
            plane and for Stage 0. Beyond ``plane_turn_bound_deg`` (its bound at the
            false-alarm probability) the stage is not ``consistent``.
    """

    checks: tuple[str, ...]
    taxel_rms_m: float
    nis: float
    nis_threshold: float
    free_space_violations: int | None
    free_space_limit: int | None
    consistent: bool
    reason: str = ""
    after_view_nis: float | None = None
    after_view_threshold: float | None = None
    plane_turn_deg: float | None = None
    plane_turn_bound_deg: float | None = None

    @property
    def contradicts_after_view(self) -> bool:
        """The after-views saw the object move otherwise than the stage's bias says."""
        if self.after_view_nis is None or self.after_view_threshold is None:
            return False
        return not self.after_view_nis <= self.after_view_threshold

    @property
    def supported(self) -> bool:
        """Consistent, and a fused stage's bias not contradicted by the after-views: what
        the selection asks of a stage (docs/method.md §9)."""
        return self.consistent and not self.contradicts_after_view

    @property
    def contradictions(self) -> str:
        """Every test the stage fails, the after-views' included; empty when supported."""
        failed = [self.reason] if self.reason else []
        if self.contradicts_after_view:
            failed.append(
                f"its bias contradicts the after-view (NIS {self.after_view_nis:.1f} > "
                f"{self.after_view_threshold:.1f})"
            )
        return "; ".join(failed)

    @property
    def passes_free_space(self) -> bool:
        """The camera's test passed (true when it did not run)."""
        if self.free_space_violations is None or self.free_space_limit is None:
            return True
        return self.free_space_violations <= self.free_space_limit

    @property
    def free_space_excess(self) -> float:
        """The points in seen free space as a share of their limit (0 when the camera's
        test did not run): how far the camera contradicts the model."""
        if self.free_space_violations is None or self.free_space_limit is None:
            return 0.0
        return self.free_space_violations / max(self.free_space_limit, 1)

    @property
    def excess(self) -> float:
        """The largest ratio of a statistic to its bound, the after-views' included (<= 1
        when :attr:`supported`): how far the evidence contradicts the model, comparable
        between stages."""
        taxels = self.nis / self.nis_threshold if np.isfinite(self.nis) else 0.0
        after_view = 0.0
        if self.after_view_nis is not None and self.after_view_threshold is not None:
            after_view = self.after_view_nis / self.after_view_threshold
        turn = 0.0
        if self.plane_turn_deg is not None and self.plane_turn_bound_deg is not None:
            turn = self.plane_turn_deg / self.plane_turn_bound_deg
        return float(max(taxels, self.free_space_excess, after_view, turn))


@dataclass(frozen=True)
class Hypothesis:
    """The alternative hypothesis a stage's model comes from when the fused model
    contradicted the evidence (:mod:`pipeline.estimation.hypotheses`).

    Attributes:
        name: ``"conditioned on free space"`` (the fused model with the plane nearest
            it that the camera accepts: :mod:`pipeline.estimation.free_space_conditioning`),
            ``"from Stage 0"`` (fused again from the initialiser's state after the fusion
            from the searched start failed: :mod:`pipeline.estimation.paper_start`),
            ``"held-plane"`` (fused again with the initialiser's plane held),
            ``"held-plane, bounded"`` (that step from Stage 0, shortened until it passes) or
            ``"earlier shape"`` (the grasps before the last, located by the last:
            :mod:`pipeline.estimation.later_grasps`; ``"earlier shape without <pad>"``
            when located by the last grasp's other pads) or ``"without <pad>"`` (fused again
            without the one pad Stage 0 alone cannot explain:
            :mod:`pipeline.estimation.outlier_pads`).
        step: the fraction of the hypothesis' step kept (1 when not bounded): from Stage 0,
            or, for ``"earlier shape"``, of the located bias from the earlier estimate's.
        replaced: why the fused model was set aside (its failed tests).
    """

    name: str
    step: float = 1.0
    replaced: str = ""

    #: What a hypothesis' name ends with when its step from Stage 0 was shortened until
    #: the model passed (:func:`pipeline.estimation.hypotheses.bounded`).
    BOUNDED_SUFFIX: ClassVar[str] = ", bounded"

    @property
    def bounded(self) -> bool:
        """The model is a shortened step from Stage 0 of a hypothesis whose full step the
        evidence contradicted (a §9 ``"<name>, bounded"``)."""
        return self.name.endswith(self.BOUNDED_SUFFIX)


@dataclass(frozen=True)
class StageEstimate:
    """The estimate after one stage: 0 (initial), 1 (bias + plane), 2 (+ points).

    Attributes:
        stage: 0, 1 or 2.
        plane, bias: the estimated symmetry plane and bias.
        covariance: ``(6, 6)`` covariance of ``(b_theta, b_x, b_y, b_z, m_r, m_theta)``;
            ``(7, 7)``, the normal's elevation ``m_phi`` appended, for a leaning plane.
        points: ``(N, 3)`` the estimated object points ``p_n`` (unbiased, camera view).
        completed: ``(2N, 3)`` the completed model ``{f_b(p_n)} U {f_mb(p_n)}`` in frame R.
        iterations: IEKF iterations used (summed over grasps; 0 for stage 0).
        status: see :data:`EstimateStatus`.
        seconds: wall time spent on this stage.
        active_points: number of points inside some taxel's gate at the end.
        trace: the state after every iteration, in order (empty for Stage 0 and estimators
            that do not iterate).
        consistency: the self-diagnosis of this stage's model, None when not assessed.
        hypothesis: the alternative hypothesis the model comes from, None when it is the
            fused (or initial) estimate itself.
        grasp_g: the state ``g`` (ordered as ``covariance``'s rows) each grasp's taxels
            are compared under, in grasp order (the bias differs between grasps when the
            object was re-grasped); empty when the estimator does not say.
        filter_covariance: the covariance of ``g`` the estimator's own iteration ended
            with, when it differs from ``covariance`` (the built-in IEKF's, which also
            counts the taxels across their normals); a later grasp is fused from it. None:
            ``covariance``.
        symmetry: the mirror plane of any orientation the stage estimated (kind
            ``"plane"``, in the unbiased frame R like ``plane``, with the covariance of its
            ``(m_r, m_azimuth, m_elevation)``), when the estimator fused a leaning plane;
            then ``g``, ``covariance`` and ``grasp_g`` have seven parameters, the plane's
            elevation ``m_phi`` last (:data:`GENERAL_PLANE_PARAMETERS`), and ``plane`` is
            the vertical plane with the same azimuth through the point of the leaning plane
            nearest the origin. None: the paper's vertical ``plane``.
    """

    stage: int
    plane: SymmetryPlane
    bias: Bias
    covariance: np.ndarray
    points: np.ndarray
    completed: np.ndarray
    iterations: int
    status: EstimateStatus
    seconds: float
    active_points: int = 0
    trace: tuple[IterationState, ...] = ()
    consistency: Consistency | None = None
    hypothesis: Hypothesis | None = None
    grasp_g: tuple[np.ndarray, ...] = ()
    filter_covariance: np.ndarray | None = None
    symmetry: Symmetry | None = None

    @property
    def estimated_symmetry(self) -> Symmetry:
        """The stage's mirror plane as a symmetry (frame R, before the bias): the leaning
        :attr:`symmetry`, else the vertical :attr:`plane` with the ``(m_r, m_theta)`` block
        of :attr:`covariance`."""
        if self.symmetry is not None:
            return self.symmetry
        return Symmetry.from_plane(self.plane, np.asarray(self.covariance)[4:, 4:])


@dataclass(frozen=True)
class EstimateResult:
    """Stages 0, 1 and 2 of one estimation run, in that order.

    Attributes:
        stages: the stages.
        selected_stage: the stage the evidence supports best (see
            :func:`pipeline.estimation.consistency.select_stage`); None means the last.
        selection_reason: why that stage was selected.
    """

    stages: tuple[StageEstimate, ...]
    selected_stage: int | None = None
    selection_reason: str = ""

    def stage(self, index: int) -> StageEstimate:
        return self.stages[index]

    @property
    def final(self) -> StageEstimate:
        return self.stages[-1]

    @property
    def selected(self) -> StageEstimate:
        """The best-supported stage (the last when no selection was made)."""
        return self.final if self.selected_stage is None else self.stages[self.selected_stage]


@dataclass(frozen=True)
class AfterView:
    """The camera's view while the hand holds the object after one grasp (docs/after-view.md).

    Attributes:
        observation: the depth image, from the same camera as the first view and through the
            same sensor model (so with the same calibration error).
        points: ``(N, 3)`` the object's visible points in it, frame ``R`` as the camera
            believes it: the points near the first view's object, above the table, less
            those the hand covers (masked by the hand's known pose, not by ground truth).
        hand_points: ``(K, 3)`` the points it sees on the hand (those the mask took out),
            the same frame.
        hand_surface: ``(S, 3)`` points on the hand's surface where its known pose puts it,
            frame ``R`` (true: the arm's kinematics, not the camera); registering
            ``hand_points`` to it measures the camera's calibration error.
        hand_normals: ``(S, 3)`` the unit normal of the hand's surface at each of them.
    """

    observation: DepthObservation
    points: np.ndarray
    hand_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    hand_surface: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    hand_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __post_init__(self) -> None:
        for name in ("points", "hand_points", "hand_surface", "hand_normals"):
            object.__setattr__(self, name, _as_points(getattr(self, name), f"AfterView.{name}"))


@dataclass(frozen=True)
class EstimationProblem:
    """Everything an estimator is given.

    Attributes:
        cloud: the segmented object cloud in frame ``R``.
        init: the Stage 0 state from the symmetry initialiser.
        grasps: one :class:`Contacts` per grasp, in the order they happened.
        view: the depth image the cloud was segmented from, when known (a trial has it,
            recorded data may not); the self-diagnosis then also checks the model against
            the space the camera saw empty.
        after_views: the camera's view after each grasp, in grasp order, None for a grasp
            without one; empty when there are none (optional: an estimator may ignore it).
    """

    cloud: PointCloud
    init: SymmetryInit
    grasps: tuple[Contacts, ...]
    view: DepthObservation | None = None
    after_views: tuple[AfterView | None, ...] = ()

    def after_view(self, k: int) -> AfterView | None:
        """The after-view of grasp ``k`` (from 0), None when it has none."""
        return self.after_views[k] if k < len(self.after_views) else None


@dataclass(frozen=True)
class ObjectPose:
    """Planar pose of an object standing on the table, frame ``R``: position of its mesh
    origin and full orientation as a quaternion ``(x, y, z, w)``."""

    position_m: np.ndarray
    quaternion_xyzw: np.ndarray

    @property
    def transform(self) -> np.ndarray:
        """``T_robot_object`` as a 4x4 matrix."""
        from scipy.spatial.transform import Rotation

        transform = np.eye(4)
        transform[:3, :3] = Rotation.from_quat(self.quaternion_xyzw).as_matrix()
        transform[:3, 3] = self.position_m
        return transform


@dataclass(frozen=True)
class GraspOutcome:
    """What executing a :class:`GraspPlan` did, as the simulator (or robot) reports it.

    Attributes:
        executed: False when the plan was refused or the hand could not reach it.
        aperture_m: final distance between the pad surfaces (parallel gripper) or the
            final finger joint angles' equivalent; NaN when not applicable.
        joint_positions: final joint positions of the hand by joint name (rad or m).
        T_robot_hand: final palm pose.
        object_before: true object pose before the grasp.
        object_after: true object pose after the grasp settled.
        reason: why it was not executed, else empty.
        reapproaches: times the descent met the object and the hand moved aside and
            descended again.
    """

    executed: bool
    aperture_m: float
    joint_positions: dict[str, float]
    T_robot_hand: np.ndarray
    object_before: ObjectPose
    object_after: ObjectPose
    reason: str = ""
    reapproaches: int = 0


@dataclass(frozen=True)
class LiftOutcome:
    """What lifting a grasped object did (:meth:`pipeline.stages.World.lift`).

    Attributes:
        held: whether the hand still held the object after the hold: it rose with the hand
            and lies between the fingers (the rule: :func:`pipeline.sim.grasp_sequence.held`).
        rise_m: how far the object's origin rose, from before the lift to the end of the
            hold, along +z of frame R (m).
        hand_rise_m: how far the palm rose over the same time (m).
        fingers_touching: fingers (of the hand's ``fingers``) in contact with the object at
            the end of the hold.
        object_before: the object's true pose before the lift.
        object_after: the object's true pose at the end of the hold.
    """

    held: bool
    rise_m: float
    hand_rise_m: float
    fingers_touching: int
    object_before: ObjectPose
    object_after: ObjectPose


class SceneObject(Protocol):
    """What a world needs to place an object (a :class:`pipeline.catalogue.objects.CatalogueObject`
    satisfies it).

    Attributes:
        name: the object's name.
        mesh: ``trimesh.Trimesh``, its surface in the object frame (metres, base on z = 0).
        mass_kg: mass (kg).
        friction: Coulomb friction coefficient (-).
        urdf_path: a URDF to load the body from (its base frame is the mesh's frame), or
            None to build the body from ``mesh``, ``mass_kg`` and ``friction``.
    """

    name: str
    mesh: Any
    mass_kg: float
    friction: float
    urdf_path: Path | None


@dataclass(frozen=True)
class SceneSetup:
    """The scene a world builds (:meth:`pipeline.stages.World.load_scene`): one object
    standing on the table, its mesh origin at ``(x_m, y_m)`` of frame ``R`` turned by
    ``yaw_rad`` about +z, and the seed of the world's random generator."""

    obj: SceneObject
    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class CameraImage:
    """A noise-free picture of the world from a pinhole camera
    (:meth:`pipeline.stages.World.render`); sensor models add their noise to it.

    Attributes:
        rgb: ``(H, W, 3) uint8`` colour image.
        depth_m: ``(H, W) float32`` true depth along the optical axis (m), ``NaN`` where
            nothing was hit between the near and far planes.
        object_mask: ``(H, W) bool``, True where the first surface along the pixel's ray
            is the object.
    """

    rgb: np.ndarray
    depth_m: np.ndarray
    object_mask: np.ndarray

    def __post_init__(self) -> None:
        shape = self.depth_m.shape
        if self.rgb.shape != (*shape, 3) or self.object_mask.shape != shape:
            raise ValueError(
                f"CameraImage: rgb {self.rgb.shape} and object_mask {self.object_mask.shape} "
                f"must match depth {shape}"
            )


@dataclass(frozen=True)
class TaxelState:
    """Every taxel of the world's hand now, in frame ``R`` (:meth:`pipeline.stages.World.
    taxels`): where it is and how far the object is from it.

    Attributes:
        positions: ``(N, 3)`` taxel centres on the pad surfaces, metres.
        normals: ``(N, 3)`` unit normals pointing out of the pads.
        pads: ``(N,)`` pad id of each taxel (str).
        taxel_indices: ``(N,)`` row-major index of each taxel within its pad.
        gaps_m: ``(N,)`` signed distance from the taxel's surface to the object along its
            normal, metres: positive a gap, negative pressed in; ``+inf`` where the object
            is not within the probed range or something else is in front of it.
        pad_forces_N: ``(N,)`` total normal force between the taxel's pad and the object,
            newtons (the same value for every taxel of a pad).
    """

    positions: np.ndarray
    normals: np.ndarray
    pads: np.ndarray
    taxel_indices: np.ndarray
    gaps_m: np.ndarray
    pad_forces_N: np.ndarray

    def __post_init__(self) -> None:
        n = len(_as_points(self.positions, "TaxelState.positions"))
        sizes = {len(_as_points(self.normals, "TaxelState.normals"))}
        sizes |= {len(np.asarray(getattr(self, f))) for f in ("pads", "taxel_indices")}
        sizes |= {len(np.asarray(getattr(self, f))) for f in ("gaps_m", "pad_forces_N")}
        if sizes != {n}:
            raise ValueError("TaxelState fields must all have one row per taxel")

    def __len__(self) -> int:
        return len(self.positions)

    def contacts(self, keep: np.ndarray) -> Contacts:
        """The taxels selected by the boolean or index array ``keep`` as :class:`Contacts`."""
        return Contacts(
            positions=self.positions[keep],
            normals=self.normals[keep],
            pads=np.asarray(self.pads)[keep],
            taxel_indices=np.asarray(self.taxel_indices)[keep],
        )
