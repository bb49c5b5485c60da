"""SDH-2 finger kinematics for planning: where each finger's distal pad sits for a base
rotation (spread) and a proximal angle, the distal link held parallel to the palm axis.

Numbers from ``robots/sdh2.urdf`` (its header explains each one). Palm frame as in
:mod:`pipeline.sim.hands`: z along the approach toward the fingertips, x toward fingers 1
and 2 (the thumb closes along +x). A finger's *facing* is the horizontal direction its
pads face (toward the palm axis at spread 60 deg); its *reach* is how far along the facing
its distal pad's surface lies from the finger base, and its proximal angle ``alpha`` is
positive when the finger flexes toward its facing. With the distal joint at ``-alpha`` the
distal link is parallel to the palm axis, so its pad meets a vertical face flat:

    reach(alpha) = PROXIMAL_LENGTH_M sin(alpha) + DISTAL_PAD_OFFSET_M
    depth(alpha) = KNUCKLE_DEPTH_M + PROXIMAL_LENGTH_M cos(alpha) + DISTAL_PAD_CENTRE_M

(``depth``: the distal pad centre below the palm origin). The hand's ``opening_m`` is
``2 (BASE_RADIUS_M - reach)``: at spread 60 deg the diameter of the circle the three distal
pads touch.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Finger order of every array here.
FINGERS = ("f1", "f2", "thumb")
#: Finger bases in the palm's xy plane (m): an equilateral triangle of 66 mm sides.
FINGER_BASES_M = np.array([[0.01905, 0.033], [0.01905, -0.033], [-0.03811, 0.0]])
#: Distance of the thumb's base from the palm axis (m); the opening is measured from it.
BASE_RADIUS_M = 0.03811
#: Finger bases' height below the palm origin (m).
BASE_DEPTH_M = 0.0745
#: Proximal (first bending) joint below the palm origin (m): 16.5 mm above the base.
KNUCKLE_DEPTH_M = BASE_DEPTH_M + 0.0165
PROXIMAL_LENGTH_M = 0.0865
DISTAL_LENGTH_M = 0.0685
#: Distal pad surface in front of the distal link's axis (m), its centre along the link (m).
DISTAL_PAD_OFFSET_M = 0.0148
DISTAL_PAD_CENTRE_M = 0.042
#: The distal pad's rows nearest the tip lie on a cylinder curving away from the object.
DISTAL_PAD_CURVED_ROWS = 9
DISTAL_PAD_CURVE_RADIUS_M = 0.059
#: Half the fingers' width across the facing (m) (29 mm links).
FINGER_HALF_WIDTH_M = 0.0145
#: Proximal link's extent across its axis: its back (28 mm thick link) and the surface of
#: the pad on its front (m).
PROXIMAL_BACK_M = -0.014
PROXIMAL_PAD_OFFSET_M = 0.0154
#: Distal link's back face behind its axis, along the facing (m).
DISTAL_BACK_M = -0.0172
#: Knuckle (base rotation housing) radius (m).
KNUCKLE_RADIUS_M = 0.0145
#: Palm housing: a cylinder of this radius down to the finger bases (m).
PALM_RADIUS_M = 0.0525
#: Bending joints' range (rad).
JOINT_LIMIT_RAD = math.pi / 2


def finger_facings(spread_rad: float) -> np.ndarray:
    """``(3, 2)`` unit facings in the palm's xy plane at base rotation ``spread_rad``:
    fingers 1 and 2 turn in opposite directions from facing the thumb (spread 0) to facing
    the palm axis (spread 60 deg); the thumb faces +x."""
    c, s = math.cos(spread_rad), math.sin(spread_rad)
    return np.array([[-c, -s], [-c, s], [1.0, 0.0]])


def reach_m(alpha_rad: float | np.ndarray) -> float | np.ndarray:
    """Distal pad surface along the facing from the finger base (module doc)."""
    return PROXIMAL_LENGTH_M * np.sin(alpha_rad) + DISTAL_PAD_OFFSET_M


def alpha_for_reach(reach: float | np.ndarray) -> float | np.ndarray:
    """Proximal angle putting the distal pad surface at ``reach`` (NaN where out of range)."""
    sine = (np.asarray(reach, dtype=np.float64) - DISTAL_PAD_OFFSET_M) / PROXIMAL_LENGTH_M
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(sine) <= 1.0, np.arcsin(np.clip(sine, -1.0, 1.0)), np.nan)


def distal_pad_depth_m(alpha_rad: float | np.ndarray) -> float | np.ndarray:
    """Distal pad centre below the palm origin (module doc)."""
    return KNUCKLE_DEPTH_M + PROXIMAL_LENGTH_M * np.cos(alpha_rad) + DISTAL_PAD_CENTRE_M


def opening_for_alpha(alpha_rad: float) -> float:
    """The hand's ``opening_m`` for a proximal angle (module doc)."""
    return 2.0 * (BASE_RADIUS_M - float(reach_m(alpha_rad)))


def alpha_for_opening(opening_m: float) -> float:
    """Proximal angle (rad, negative = outward) giving ``opening_m``."""
    return math.asin((BASE_RADIUS_M - opening_m / 2.0 - DISTAL_PAD_OFFSET_M) / PROXIMAL_LENGTH_M)


def finger_profile(alpha_rad: float, step_m: float = 0.001) -> tuple[np.ndarray, np.ndarray]:
    """The lowest point of a finger (knuckle, proximal and distal link) at each distance
    along its facing, with the distal link parallel to the palm axis.

    A finger descending vertically sweeps everything above this profile: an object point
    at distance ``t`` along the facing and depth ``d`` below the palm is hit on the way
    down when ``d <= depth[t]``.

    Returns:
        ``(t, depth)``: ``t`` a grid of distances from the finger base (m, ``step_m``
        apart), ``depth`` the finger's greatest depth below the palm there (m), ``-inf``
        where no part of the finger is.
    """
    s, c = math.sin(alpha_rad), math.cos(alpha_rad)
    # Knuckle: a cylinder about the base's vertical axis, down to the proximal joint.
    t_knuckle = np.arange(-KNUCKLE_RADIUS_M, KNUCKLE_RADIUS_M + step_m / 2, step_m)
    knuckle = np.column_stack([t_knuckle, np.full_like(t_knuckle, KNUCKLE_DEPTH_M)])
    # Proximal link with its pad: from the joint along (sin, cos) for its length.
    along, across = np.meshgrid(
        np.arange(0.0, PROXIMAL_LENGTH_M + step_m / 4, step_m / 2),
        np.arange(PROXIMAL_BACK_M, PROXIMAL_PAD_OFFSET_M + step_m / 4, step_m / 2),
    )
    proximal = np.column_stack(
        [
            along.ravel() * s + across.ravel() * c,
            KNUCKLE_DEPTH_M + along.ravel() * c - across.ravel() * s,
        ]
    )
    # Distal link, vertical, from its back face to the pad surface, down to the tip.
    joint_t = PROXIMAL_LENGTH_M * s
    tip_depth = KNUCKLE_DEPTH_M + PROXIMAL_LENGTH_M * c + DISTAL_LENGTH_M
    t_distal = np.arange(
        joint_t + DISTAL_BACK_M, joint_t + DISTAL_PAD_OFFSET_M + step_m / 2, step_m
    )
    distal = np.column_stack([t_distal, np.full_like(t_distal, tip_depth)])
    samples = np.concatenate([knuckle, proximal, distal])
    grid = np.arange(samples[:, 0].min() - step_m, samples[:, 0].max() + 2 * step_m, step_m)
    depth = np.full(len(grid), -np.inf)
    index = np.clip(np.round((samples[:, 0] - grid[0]) / step_m).astype(int), 0, len(grid) - 1)
    np.maximum.at(depth, index, samples[:, 1])
    return grid, depth


def closing_hits(
    t_m: np.ndarray, depth_m: np.ndarray, alphas_rad: Sequence[float], clearance_m: float
) -> np.ndarray:
    """``(K, N)``: which points, at distance ``t_m`` along a finger's facing from its base
    and ``depth_m`` below the palm (both ``(N,)``, within the finger's width), lie inside
    the finger's knuckle or proximal link with pad, grown by ``clearance_m``, at each of the
    ``K`` proximal angles ``alphas_rad``. The distal link is left out: its pad is where the
    finger means to touch, and its tip only ever moves toward the surface that pad meets."""
    knuckle = (np.abs(t_m) <= KNUCKLE_RADIUS_M + clearance_m) & (
        (depth_m >= BASE_DEPTH_M - clearance_m) & (depth_m <= KNUCKLE_DEPTH_M + clearance_m)
    )
    s = np.array([math.sin(alpha) for alpha in alphas_rad])[:, None]
    c = np.array([math.cos(alpha) for alpha in alphas_rad])[:, None]
    relative_d = depth_m - KNUCKLE_DEPTH_M
    along = t_m * s + relative_d * c
    across = t_m * c - relative_d * s
    proximal = (
        (along >= -clearance_m)
        & (along <= PROXIMAL_LENGTH_M + clearance_m)
        & (across >= PROXIMAL_BACK_M - clearance_m)
        & (across <= PROXIMAL_PAD_OFFSET_M + clearance_m)
    )
    return knuckle | proximal
