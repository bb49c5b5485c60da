"""An estimated mirror plane or rotation axis scored against an object's true symmetries.

An object may have several true symmetries (a box: three planes; a can: an axis and the
plane across it), and the estimate is scored against the one it comes nearest to by angle.
A plane is a symmetry of a body of revolution when it contains the axis, so an estimated
plane is compared with a true axis by how far it is from containing it; an estimated axis
is compared with true axes only (a mirror plane does not make a body of revolution).

A sphere (two true axes apart) is symmetric about every axis and plane through its centre.
The offset error is measured where the object is: the distance from the estimate of the true
symmetry's point nearest the object's centre (its projection on the true plane or axis).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from pipeline.types import Symmetry


def nearest_point(symmetry: Symmetry, point_m: np.ndarray) -> np.ndarray:
    """The point of the plane or axis nearest ``point_m`` (3,)."""
    point = np.asarray(point_m, dtype=np.float64)
    along = float((point - symmetry.point_m) @ symmetry.direction)
    if symmetry.is_plane:
        return point - along * symmetry.direction
    return symmetry.point_m + along * symmetry.direction


def distance_to(symmetry: Symmetry, point_m: np.ndarray) -> float:
    """Distance of ``point_m`` (3,) from the plane or the axis (m)."""
    return float(
        np.linalg.norm(np.asarray(point_m, dtype=np.float64) - nearest_point(symmetry, point_m))
    )


def round_centre(truths: Sequence[Symmetry], distinct_deg: float = 10.0) -> np.ndarray | None:
    """The centre of a sphere, when two of the true axes differ in direction by more than
    ``distinct_deg`` (the search lists a few of a sphere's infinitely many axes); else
    None. The centre is the point of the first axis nearest the second's point."""
    axes = [truth for truth in truths if not truth.is_plane]
    for index, first in enumerate(axes):
        for second in axes[index + 1 :]:
            if abs(float(first.direction @ second.direction)) < math.cos(
                math.radians(distinct_deg)
            ):
                return nearest_point(first, second.point_m)
    return None


def pair_errors(
    estimated: Symmetry, truth: Symmetry, centre_m: np.ndarray
) -> tuple[float, float] | None:
    """``(angle_deg, offset_mm)`` of an estimate against one true symmetry, or None when the
    two cannot be compared (an estimated axis against a true plane)."""
    cosine = min(1.0, abs(float(estimated.direction @ truth.direction)))
    if estimated.is_plane and not truth.is_plane:
        # The plane should contain the axis: its normal perpendicular to the axis.
        angle = math.degrees(math.asin(cosine))
    elif estimated.is_plane == truth.is_plane:
        angle = math.degrees(math.acos(cosine))
    else:
        return None
    anchor = nearest_point(truth, centre_m)
    return angle, distance_to(estimated, anchor) * 1e3


def symmetry_errors(
    estimated: Symmetry, truths: Sequence[Symmetry], centre_m: np.ndarray
) -> dict[str, float | str]:
    """``symmetry_angle_error_deg``, ``symmetry_offset_error_mm`` and ``symmetry_truth_kind``
    against the true symmetry nearest by angle (then offset); empty when no true symmetry
    compares with the estimate.

    Args:
        estimated: the estimated plane or axis, frame R.
        truths: the object's true symmetries in the same frame.
        centre_m: ``(3,)`` the object's centre (m), where offsets are measured.
    """
    centre = round_centre(truths)
    if centre is not None:
        # A sphere: every axis through its centre, and every plane, is a symmetry.
        along = estimated.direction if not estimated.is_plane else estimated.across_axes()[0]
        truths = [*truths, Symmetry("axis", along, centre)]
    scored = []
    for truth in truths:
        errors = pair_errors(estimated, truth, centre_m)
        if errors is not None:
            scored.append((errors, truth.kind))
    if not scored:
        return {}
    (angle, offset), kind = min(scored, key=lambda item: item[0])
    return {
        "symmetry_angle_error_deg": angle,
        "symmetry_offset_error_mm": offset,
        "symmetry_truth_kind": kind,
    }


#: A true axis within this angle of +z is vertical, a plane's normal within it of the table
#: level (deg): the tolerance of an object resting on the table, and of a grasp's tilt.
LEVEL_DEG = 5.0


def true_kind(truths: Sequence[Symmetry]) -> str:
    """Which kind of symmetry (:data:`pipeline.types.SYMMETRY_KINDS`) describes an object as
    it lies, frame R (z up), the most constrained first, or ``"none"``.

    ``"axis"``: a body of revolution in any pose (a true axis of any direction: a can
    standing or on its side), or a sphere. ``"vertical-plane"``: a true mirror plane within
    :data:`LEVEL_DEG` of vertical. ``"plane"``: only mirror planes that are not vertical (a
    box resting on an edge). ``"none"``: no true symmetry.
    """
    level = math.sin(math.radians(LEVEL_DEG))
    if any(not truth.is_plane for truth in truths):
        return "axis"
    if any(abs(truth.direction[2]) <= level for truth in truths):
        return "vertical-plane"
    return "plane" if truths else "none"
