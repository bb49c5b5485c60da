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


def front_to_back(points_robot: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """``direction`` (horizontal unit) or its negative, whichever points from the visible
    (camera) side of the cloud to its hidden back, judged by the lower quarter of the
    cloud's height lying on the front side of the centroid."""
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
) -> PadBand:
    """Pad placement covering the object's upper part: the pad's top edge ``top_margin_m``
    below the cloud's top (98th height percentile, robust to noise), raised if needed so
    the fingertip (``pad_centre_to_fingertip_m`` below the pad centre) stays
    ``table_clearance_m`` above the table."""
    length, width = pad.rows * pad.pitch_m, pad.cols * pad.pitch_m
    z_top = float(np.percentile(points_robot[:, 2], 98.0))
    lowest = table_height_m + table_clearance_m + pad_centre_to_fingertip_m
    return PadBand(max(z_top - top_margin_m - length / 2, lowest), length, width)


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
        predicted_contacts: ``(K, 3)`` cloud points the front pad touches first.
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
) -> ParallelGrasp | None:
    """Place a parallel gripper opened to ``opening_m`` so the front jaw stands
    ``jaw_clearance_m`` in front of the visible surface on the line through ``centre_m``.

    Args:
        points_robot: ``(N, 3)`` visible cloud.
        completed_robot: ``(M, 3)`` cloud completed by the proposed plane (for the width).
        centre_m: point the closing line passes through (the object centre on the plane).
        closing_direction: horizontal unit vector, front to back.
        band: where the pads sit.
        opening_m: jaw opening between the pad surfaces.
        jaw_clearance_m: gap between the front pad and the visible surface.
        palm_above_pad_centre_m: palm origin height above the pad centre.
        contact_band_m: depth of the surface layer reported as predicted contacts.

    Returns:
        The grasp, or None when no visible point lies between the pads' paths.
    """
    reachable = corridor(points_robot, centre_m, closing_direction, band)
    if not np.any(reachable):
        return None
    front, contacts = first_touched(points_robot, reachable, closing_direction, contact_band_m)
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
#: at 180 deg (front), fingers 1 and 2 at +-60 deg (HARDWARE.md finger base triangle).
SDH_FINGER_ANGLES_RAD = (np.pi, np.pi / 3, -np.pi / 3)


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
) -> CylindricalGrasp:
    """A top grasp toward the centroid of the completed cloud, fingers closing radially.

    Args:
        completed_robot: ``(M, 3)`` cloud completed by mirroring.
        closing_direction: horizontal unit x axis of the palm (thumb side to finger side).
        band: where the finger pads sit.
        palm_above_pad_centre_m: palm origin height above the pad centre.
        contact_band_m: depth of the surface layer reported as predicted contacts.
        finger_angles_rad: bearing of each finger about the palm axis, from +x.
    """
    centre = completed_robot.mean(axis=0)
    contacts = []
    for angle in finger_angles_rad:
        outward = rotate_z(closing_direction, angle)
        reachable = corridor(completed_robot, centre, outward, band)
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
