"""Top grasps from a single-view cloud and a symmetry plane (paper sections 4.1, 4.2).

Hand pose convention (``GraspPlan.T_robot_hand``): the palm frame's z axis points down the
approach direction (toward the table), its x axis is the closing direction and points from
the *front* finger (the jaw, or the SDH thumb, on the camera side) to the back, and
``y = z x x``. The palm origin lies on the hand's axis of symmetry.

The planner has no camera pose, so the *visible side* is inferred from the cloud itself: a
single top-down-ish view sees an object's lower part only on the side facing the camera
(the back is occluded down to the table), so the lower quarter of the cloud's height lies
on the front side of the cloud's centroid.

Pads: ``PadLayout.rows`` taxels run along the finger (the pad's length ``rows * pitch``),
``cols`` across it (its width).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.types import PadLayout


@dataclass(frozen=True)
class PadBand:
    """Where a pad sits: its centre height ``z_centre_m`` and its length/width (m)."""

    z_centre_m: float
    length_m: float
    width_m: float

    @property
    def z_range_m(self) -> tuple[float, float]:
        return self.z_centre_m - self.length_m / 2, self.z_centre_m + self.length_m / 2


def rotate_z(vector: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rotate a ``(3,)`` vector about +z."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1], vector[2]])


def front_to_back(
    points_robot: np.ndarray, direction: np.ndarray, viewpoint_m: np.ndarray | None = None
) -> np.ndarray:
    """``direction`` (horizontal unit) or its negative, whichever points from the visible
    (camera) side of the cloud to its hidden back: away from the camera at ``viewpoint_m``
    (frame R) when it is known, else judged by the lower quarter of the cloud's height
    lying on the front side of the centroid (a camera looking down sees an object's
    bottom in front of its top; a wall seen level, such as a cup's, leaves that guess to
    chance)."""
    if viewpoint_m is not None:
        away = points_robot.mean(axis=0) - viewpoint_m
        return direction if away[:2] @ direction[:2] >= 0.0 else -direction
    z = points_robot[:, 2]
    low = z <= z.min() + 0.25 * (z.max() - z.min())
    shift = (points_robot[low].mean(axis=0) - points_robot.mean(axis=0)) @ direction
    return -direction if shift > 0.0 else direction


def hand_pose(position_m: np.ndarray, closing_direction: np.ndarray) -> np.ndarray:
    """``T_robot_hand`` with x = ``closing_direction`` (horizontal), z down, at ``position_m``."""
    x_axis = np.array([closing_direction[0], closing_direction[1], 0.0])
    x_axis /= np.linalg.norm(x_axis)
    z_axis = np.array([0.0, 0.0, -1.0])
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis])
    T[:3, 3] = position_m
    return T


def pad_band(
    points_robot: np.ndarray,
    pad: PadLayout,
    *,
    table_height_m: float,
    top_margin_m: float,
    pad_centre_to_fingertip_m: float,
    table_clearance_m: float,
    keep_above_cloud: bool = False,
) -> PadBand:
    """Pad placement covering the object's upper part: the pad's top edge ``top_margin_m``
    below the cloud's top (98th height percentile, robust to noise), raised if needed so
    the fingertip (``pad_centre_to_fingertip_m`` below the pad centre) stays
    ``table_clearance_m`` above the table and, with ``keep_above_cloud``, so the pad's lower
    edge stays above the cloud's bottom (2nd height percentile): taxels below the segmented
    cloud would touch surface that no cloud point represents, and pull the fused model
    down. On an object shorter than the pad plus the segmentation's height cut the pad
    then reaches above the object's top."""
    length, width = pad.rows * pad.pitch_m, pad.cols * pad.pitch_m
    z_bottom, z_top = np.percentile(points_robot[:, 2], [2.0, 98.0])
    lowest = table_height_m + table_clearance_m + pad_centre_to_fingertip_m
    if keep_above_cloud:
        lowest = max(lowest, float(z_bottom) + length / 2)
    return PadBand(max(float(z_top) - top_margin_m - length / 2, lowest), length, width)


def corridor(
    points_robot: np.ndarray,
    centre_m: np.ndarray,
    direction: np.ndarray,
    band: PadBand,
) -> np.ndarray:
    """Mask of the points a pad of ``band`` moving along ``direction`` (horizontal unit)
    through ``centre_m`` can touch: within half the pad width of the line, inside its
    height range."""
    lateral = np.array([-direction[1], direction[0], 0.0])
    z_low, z_high = band.z_range_m
    return (
        (np.abs((points_robot - centre_m) @ lateral) <= band.width_m / 2)
        & (points_robot[:, 2] >= z_low)
        & (points_robot[:, 2] <= z_high)
    )


def first_touched(
    points_robot: np.ndarray, mask: np.ndarray, direction: np.ndarray, band_m: float
) -> tuple[float, np.ndarray]:
    """The surface a finger moving along ``direction`` meets first among
    ``points_robot[mask]``: the points within ``band_m`` behind the 2nd percentile of their
    projections onto ``direction`` (robust to noisy outliers in front), and the median
    projection of those points (the surface's position, unbiased by depth noise as long as
    ``band_m`` spans the noise)."""
    candidates = points_robot[mask]
    along = candidates @ direction
    layer = along <= np.percentile(along, 2.0) + band_m
    return float(np.median(along[layer])), candidates[layer]


#: Residuals beyond this many robust sigmas are dropped before the surface is refitted.
_TRIM_SIGMAS = 3.0
#: Fewest layer points a surface fit needs (five unknowns); fewer: the layer's median.
_MIN_FIT_POINTS = 12


def pad_touch(
    points_robot: np.ndarray,
    mask: np.ndarray,
    centre_m: np.ndarray,
    direction: np.ndarray,
    *,
    band_m: float,
    half_width_m: float,
    flat_radius_m: float,
    touch_depth_m: float,
) -> tuple[float, np.ndarray]:
    """Where a flat pad moving along ``direction`` first touches the surface among
    ``points_robot[mask]``, and the cloud points it touches there.

    The surface is the :func:`first_touched` layer. Its depth along ``direction`` is fitted
    by least squares (one trimming pass at 3 robust sigmas) as
    ``d = a + b u + e u^2 + c (z - z_mean) + g (z - z_mean)^2``, ``u`` the lateral offset
    from the closing line through ``centre_m``. A curved face (``e`` above
    ``1 / (2 flat_radius_m)``: radius of curvature below ``flat_radius_m``) is first
    touched at its extreme ``u* = -b / 2e``, clipped to the pad's ``half_width_m``, and the
    touch position is the fit at ``(u*, z_mean)``: the depth noise averages out instead of
    biasing the layer's median backward (a cylinder of radius r across a pad of half-width
    w: about ``w^2 / 6r``). A flatter face is left to :func:`first_touched` (its median and
    layer), which is unbiased there.

    Returns:
        The touch position (projection on ``direction``, m) and the ``(K, 3)`` layer points
        whose fitted depth lies within ``touch_depth_m`` of it, moved onto the pad's plane
        (their centroid's projection is the touch position). For a flat face, or fewer
        than ``_MIN_FIT_POINTS`` layer points: the :func:`first_touched` median and layer.
    """
    median, layer = first_touched(points_robot, mask, direction, band_m)
    if len(layer) < _MIN_FIT_POINTS:
        return median, layer
    lateral = np.array([-direction[1], direction[0], 0.0])
    u = (layer - centre_m) @ lateral
    dz = layer[:, 2] - layer[:, 2].mean()
    depth = layer @ direction
    design = np.column_stack([np.ones_like(u), u, u * u, dz, dz * dz])
    keep = np.ones(len(u), dtype=bool)
    for _ in range(2):
        coef = np.linalg.lstsq(design[keep], depth[keep], rcond=None)[0]
        residual = depth - design @ coef
        sigma = 1.4826 * np.median(np.abs(residual[keep])) + 1e-9
        keep = np.abs(residual) <= _TRIM_SIGMAS * sigma
    a, b, e = coef[:3]
    if e <= 1.0 / (2.0 * flat_radius_m):
        return median, layer
    u_touch = float(np.clip(-b / (2.0 * e), -half_width_m, half_width_m))
    touch = float(a + b * u_touch + e * u_touch**2)
    fitted = a + b * u + e * u * u
    touched = layer[fitted <= touch + touch_depth_m]
    return touch, touched + np.outer(touch - touched @ direction, direction)


@dataclass(frozen=True)
class ParallelGrasp:
    """Geometry of a parallel-jaw top grasp (robot frame, metres).

    Attributes:
        T_robot_hand: palm pose.
        closing_direction: unit x axis, from the front jaw to the back jaw.
        front_contact_m: projection of the front surface on the closing direction.
        width_m: from the visible front surface to the far end (98th percentile) of the
            reachable visible and completed points, along the closing direction (mirrored points in
            front of the visible surface are ignored: they cannot be there).
        predicted_contacts: ``(K, 3)`` cloud points the front pad touches first, moved
            onto the pad's plane (:func:`pad_touch`).
    """

    T_robot_hand: np.ndarray
    closing_direction: np.ndarray
    front_contact_m: float
    width_m: float
    predicted_contacts: np.ndarray


def parallel_top_grasp(
    points_robot: np.ndarray,
    completed_robot: np.ndarray,
    centre_m: np.ndarray,
    closing_direction: np.ndarray,
    band: PadBand,
    *,
    opening_m: float,
    jaw_clearance_m: float,
    palm_above_pad_centre_m: float,
    contact_band_m: float,
    flat_radius_m: float = 0.15,
    touch_depth_m: float = 0.001,
) -> ParallelGrasp | None:
    # Eleven parameters: a numeric kernel given the cloud, the line and the hand's distances.
    """Place a parallel gripper opened to ``opening_m`` so the front jaw stands
    ``jaw_clearance_m`` in front of the visible surface on the line through ``centre_m``.
    The visible surface's position is where the front pad first touches it
    (:func:`pad_touch`).

    Args:
        points_robot: ``(N, 3)`` visible cloud.
        completed_robot: ``(M, 3)`` cloud completed by the proposed plane (for the width).
        centre_m: point the closing line passes through (the object centre on the plane).
        closing_direction: horizontal unit vector, front to back.
        band: where the pads sit.
        opening_m: jaw opening between the pad surfaces.
        jaw_clearance_m: gap between the front pad and the visible surface.
        palm_above_pad_centre_m: palm origin height above the pad centre.
        contact_band_m: depth of the visible surface layer the pad's touch is fitted to.
        flat_radius_m: faces curved less than this radius count as flat (:func:`pad_touch`).
        touch_depth_m: surface within this depth of the touch counts as touched.

    Returns:
        The grasp, or None when no visible point lies between the pads' paths.
    """
    reachable = corridor(points_robot, centre_m, closing_direction, band)
    if not np.any(reachable):
        return None
    front, contacts = pad_touch(
        points_robot,
        reachable,
        centre_m,
        closing_direction,
        band_m=contact_band_m,
        half_width_m=band.width_m / 2,
        flat_radius_m=flat_radius_m,
        touch_depth_m=touch_depth_m,
    )
    behind = completed_robot[corridor(completed_robot, centre_m, closing_direction, band)]
    along = np.concatenate([points_robot[reachable], behind]) @ closing_direction
    back = float(np.percentile(along, 98.0))
    centre_along = front - jaw_clearance_m + opening_m / 2
    position = centre_m + (centre_along - centre_m @ closing_direction) * closing_direction
    position[2] = band.z_centre_m + palm_above_pad_centre_m
    return ParallelGrasp(
        T_robot_hand=hand_pose(position, closing_direction),
        closing_direction=closing_direction,
        front_contact_m=front,
        width_m=back - front,
        predicted_contacts=contacts,
    )


#: SDH finger directions from the palm axis in the palm frame at spread 60 degrees: thumb
#: at 180 deg (front), fingers 1 and 2 at +-60 deg (the SDH-2's finger base triangle).
SDH_FINGER_ANGLES_RAD = (np.pi, np.pi / 3, -np.pi / 3)
#: Finger directions at spread 0: thumb, finger 1, finger 2 (fingers 1 and 2 face the thumb,
#: closing along -x; their lateral offsets are the hand's finger bases,
#: :meth:`pipeline.planning.sdh_candidates.SdhHand.parallel_finger_offsets_m`).
SDH_PARALLEL_FINGER_ANGLES_RAD = (np.pi, 0.0, 0.0)


def back_face_is_flat(
    completed_robot: np.ndarray,
    closing_direction: np.ndarray,
    band: PadBand,
    *,
    half_span_m: float,
    band_m: float,
    flat_radius_m: float,
) -> bool:
    """Whether the completed cloud's back face, seen along ``-closing_direction`` within
    ``half_span_m`` either side of the closing line through the centroid and inside the pad
    band's heights, is flat and spans that width: its first-touched layer (``band_m`` deep)
    reaches both ends of the span and a quadratic ``d = a + b u + e u^2`` fitted to its depth
    has a radius of curvature ``1 / 2|e|`` above ``flat_radius_m``. A flat back is grasped
    best with the SDH-2's fingers facing the thumb (spread 0): their pads lie flat on it,
    where at 120 deg apart the pads' edges would meet it first."""
    centre = completed_robot.mean(axis=0)
    backward = -np.asarray(closing_direction, dtype=np.float64)
    span = PadBand(band.z_centre_m, band.length_m, 2.0 * half_span_m)
    mask = corridor(completed_robot, centre, backward, span)
    if np.count_nonzero(mask) < 12:
        return False
    _, layer = first_touched(completed_robot, mask, backward, band_m)
    lateral = np.array([-backward[1], backward[0], 0.0])
    u = (layer - centre) @ lateral
    if len(layer) < 12 or u.min() > -0.8 * half_span_m or u.max() < 0.8 * half_span_m:
        return False
    design = np.column_stack([np.ones_like(u), u, u * u])
    e = np.linalg.lstsq(design, layer @ backward, rcond=None)[0][2]
    return bool(abs(e) < 1.0 / (2.0 * flat_radius_m))


@dataclass(frozen=True)
class CylindricalGrasp:
    """Geometry of a three-finger cylindrical top grasp (robot frame, metres).

    Attributes:
        T_robot_hand: palm pose (on the completed cloud's centroid line).
        closing_direction: unit x axis (thumb side to finger side).
        width_m: extent of the completed cloud's reachable points along x.
        predicted_contacts: ``(K, 3)`` completed-cloud points the fingers touch first,
            thumb's first, then finger 1's and finger 2's.
    """

    T_robot_hand: np.ndarray
    closing_direction: np.ndarray
    width_m: float
    predicted_contacts: np.ndarray


def cylindrical_top_grasp(
    completed_robot: np.ndarray,
    closing_direction: np.ndarray,
    band: PadBand,
    *,
    palm_above_pad_centre_m: float,
    contact_band_m: float,
    finger_angles_rad: tuple[float, ...] = SDH_FINGER_ANGLES_RAD,
    finger_offsets_m: tuple[float, ...] | None = None,
) -> CylindricalGrasp:
    """A top grasp toward the centroid of the completed cloud, fingers closing radially.

    Args:
        completed_robot: ``(M, 3)`` cloud completed by mirroring.
        closing_direction: horizontal unit x axis of the palm (thumb side to finger side).
        band: where the finger pads sit.
        palm_above_pad_centre_m: palm origin height above the pad centre.
        contact_band_m: depth of the surface layer reported as predicted contacts.
        finger_angles_rad: bearing of each finger about the palm axis, from +x.
        finger_offsets_m: each finger's closing line, shifted this far along the palm's y
            axis from the palm axis (None: all on the axis).
    """
    centre = completed_robot.mean(axis=0)
    y_hand = np.cross([0.0, 0.0, -1.0], closing_direction)
    offsets = finger_offsets_m or (0.0,) * len(finger_angles_rad)
    contacts = []
    for angle, offset in zip(finger_angles_rad, offsets, strict=True):
        outward = rotate_z(closing_direction, angle)
        reachable = corridor(completed_robot, centre + offset * y_hand, outward, band)
        if np.any(reachable):
            contacts.append(first_touched(completed_robot, reachable, -outward, contact_band_m)[1])
    wide = corridor(completed_robot, centre, closing_direction, band)
    along = completed_robot[wide if np.any(wide) else slice(None)] @ closing_direction
    position = np.array([centre[0], centre[1], band.z_centre_m + palm_above_pad_centre_m])
    return CylindricalGrasp(
        T_robot_hand=hand_pose(position, closing_direction),
        closing_direction=closing_direction,
        width_m=float(along.max() - along.min()),
        predicted_contacts=np.concatenate(contacts) if contacts else np.zeros((0, 3)),
    )


def narrowest_width(points_xy: np.ndarray) -> tuple[float, float]:
    """The smallest width of a planar point set and the direction it is measured along.

    Rotating calipers: the minimum width of a convex polygon is attained with one hull edge
    flush against a caliper, so only the hull edges' normals need testing.

    Args:
        points_xy: ``(N, 2)`` points (m), e.g. a mesh's vertices projected onto the table.

    Returns:
        ``(width_m, direction_rad)``: the width and the angle of the measuring direction
        about +z, in [0, pi).
    """
    points_xy = np.asarray(points_xy, dtype=np.float64)
    from scipy.spatial import ConvexHull  # deferred: planners load with `plugins`

    hull = points_xy[ConvexHull(points_xy).vertices]
    edges = np.roll(hull, -1, axis=0) - hull
    normals = np.column_stack([-edges[:, 1], edges[:, 0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    projections = hull @ normals.T
    widths = projections.max(axis=0) - projections.min(axis=0)
    best = int(np.argmin(widths))
    direction = math.atan2(normals[best, 1], normals[best, 0]) % math.pi
    return float(widths[best]), direction
