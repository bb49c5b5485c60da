"""Length units of input files, and the scale check that catches millimetres.

symfuse works in metres. A cloud, taxel file or mesh written in millimetres reads as an
object a thousand times too large and too far away; the estimator then runs on nonsense and
ends ``diverged`` with no hint why. Readers therefore convert by ``--units`` and check the
scale of what they read: no point a tabletop robot sees or touches lies :data:`FARTHEST_M`
from its base (the depth sensors see at most 4 m, the hands reach about 1 m), and no object
a hand grasps is :data:`LARGEST_OBJECT_M` across; in millimetres, every real object breaks
both (a point 10 mm from the base reads as 10 m).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from pipeline.errors import InputError

Units = Literal["m", "mm"]
"""The length units a file or an option may be given in."""
UNIT_SCALE: dict[str, float] = {"m": 1.0, "mm": 1e-3}
"""Metres per unit."""
#: Farther from the robot base than this (m), a point is not on a tabletop object.
FARTHEST_M = 10.0
#: Larger than this (m, the largest bounding-box extent), an object is not graspable.
LARGEST_OBJECT_M = 2.0

#: Smaller than this (m, the largest bounding-box extent), no hand grasps an object: data
#: read as millimetres that is that small was in metres.
SMALLEST_OBJECT_M = 0.005

MILLIMETRES_HINT = "looks like millimetres: pass --units mm"
#: The hint for a file whose format fixes metres (camera.json): no option converts it.
UNITS_IN_METRES = "looks like millimetres: the file must be in metres"
#: The hint for a file that states its own units (a contacts file).
STATED_UNITS_HINT = 'looks like millimetres: set the file\'s "units" to "mm"'


def scale_of(units: str, source: str) -> float:
    """Metres per unit of ``units`` (``m`` or ``mm``).

    Raises:
        InputError: unknown units; the message names ``source``.
    """
    if units not in UNIT_SCALE:
        raise InputError(f"{source}: unknown units {units!r} (use 'm' or 'mm')")
    return UNIT_SCALE[units]


def check_distance(points_m: np.ndarray, source: str, hint: str | None = MILLIMETRES_HINT) -> None:
    """Refuse points (frame R, metres) farther than :data:`FARTHEST_M` from the robot base.

    Args:
        hint: what to do about millimetres (``--units mm`` where the command has it); None
            when the data were read as millimetres already. It is given only when the
            points, read as millimetres, would be near enough.

    Raises:
        InputError: ``"<source>: a point lies 512 m from the robot base: looks like
            millimetres: pass --units mm"``.
    """
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    if len(points_m) == 0:
        return
    # Coordinates near the float limit overflow when squared: that is "too far", not a
    # warning to print.
    with np.errstate(over="ignore"):
        farthest = float(np.max(np.linalg.norm(points_m, axis=1)))
    if farthest > FARTHEST_M:
        if hint is None or farthest * UNIT_SCALE["mm"] > FARTHEST_M:
            hint = "no tabletop object lies that far, in metres or millimetres"
        raise InputError(f"{source}: a point lies {farthest:.3g} m from the robot base: {hint}")


def check_extent(extents_m: np.ndarray, source: str, hint: str = MILLIMETRES_HINT) -> None:
    """Refuse an object whose largest bounding-box extent exceeds :data:`LARGEST_OBJECT_M`.

    Args:
        hint: what to do about it (a URDF states its scale itself, not by ``--units``).

    Raises:
        InputError: ``"<source>: the object is 120 m across: looks like millimetres: pass
            --units mm"``.
    """
    largest = float(np.max(extents_m))
    if largest > LARGEST_OBJECT_M:
        raise InputError(f"{source}: the object is {largest:.3g} m across: {hint}")


def check_not_metres(extents_m: np.ndarray, units: str, source: str) -> None:
    """Refuse data read as ``units="mm"`` whose object is smaller than
    :data:`SMALLEST_OBJECT_M`: it was in metres (``--units mm`` given by mistake).

    Raises:
        InputError: ``"<source>: the object is 0.04 mm across: looks like metres: drop
            --units mm"``.
    """
    largest = float(np.max(extents_m))
    if units == "mm" and largest < SMALLEST_OBJECT_M:
        raise InputError(
            f"{source}: the object is {largest * 1e3:.3g} mm across: looks like metres: "
            "drop --units mm"
        )


def check_stated_not_metres(points_m: np.ndarray, units: str, source: str) -> None:
    """Refuse points (frame R, metres) of a file that says it is in millimetres when every
    one lies within :data:`FARTHEST_M` x 1e-3 of the robot base: the file was in metres
    (read as millimetres, a point :data:`FARTHEST_M` away or nearer lands that near), and
    no tabletop object is touched that near the base.

    Raises:
        InputError: ``"<source>: every point lies within 0.612 mm of the robot base: looks
            like metres: set the file's "units" to "m"``.
    """
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    if units != "mm" or len(points_m) == 0:
        return
    farthest = float(np.max(np.linalg.norm(points_m, axis=1)))
    if farthest < FARTHEST_M * UNIT_SCALE["mm"]:
        raise InputError(
            f"{source}: every point lies within {farthest * 1e3:.3g} mm of the robot base: "
            'looks like metres: set the file\'s "units" to "m"'
        )
