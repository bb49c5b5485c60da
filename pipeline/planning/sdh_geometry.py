"""SDH-2 finger kinematics for planning: where each finger's distal pad sits for a base
rotation (spread) and a proximal angle, the distal link held parallel to the palm axis.

:class:`FingerKinematics` holds a turn-and-bend hand's numbers, read from its URDF
(:class:`pipeline.types.BendingFinger`, :func:`pipeline.io.hand_urdf.read_hand_geometry`).
Palm frame as in :mod:`pipeline.sim.hands`: z along the approach toward the fingertips, x
toward fingers 1 and 2 (the thumb closes along +x). A finger's *facing* is the horizontal
direction its pads face (toward the palm axis at spread 60 deg); its *reach* is how far
along the facing its distal pad's surface lies from the finger base, and its proximal
angle ``alpha`` is positive when the finger flexes toward its facing. With the distal
joint at ``-alpha`` the distal link is parallel to the palm axis, so its pad meets a
vertical face flat:

    reach(alpha) = proximal_length_m sin(alpha) + distal_pad_offset_m
    depth(alpha) = knuckle_depth_m + proximal_length_m cos(alpha) + distal_pad_centre_m

(``depth``: the distal pad centre below the palm origin). The hand's ``opening_m`` is
``2 (base_radius_m - reach)``: at spread 60 deg the diameter of the circle the three
distal pads touch.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.errors import ConfigError
from pipeline.types import HandGeometry

#: The distal pad's rows nearest the tip lie on a cylinder curving away from the object: the
#: tactile pad's layout (Weiss DSA 9205), not the URDF's.
DISTAL_PAD_CURVED_ROWS = 9
DISTAL_PAD_CURVE_RADIUS_M = 0.059


@dataclass(frozen=True, eq=False)
class FingerKinematics:
    """A turn-and-bend hand's planning numbers (m, rad; palm frame), every finger alike but
    for its base and facing.

    Attributes:
        fingers: the fingers' names, the order of every array here.
        bases_m: ``(F, 2)`` the base joints' origins in the palm's xy plane.
        facings: ``(F, 2)`` the directions the fingers face at spread 0.
        spread_signs: how each facing turns with the spread (``1``, ``-1``, ``0``).
        base_radius_m: the fixed finger's (the thumb's) base distance from the palm axis;
            the opening is measured from it.
        base_depth_m: the finger bases below the palm origin.
        knuckle_depth_m: the first bending joint below the palm origin.
        proximal_length_m, distal_length_m: the links' lengths (the distal one to the tip).
        distal_pad_offset_m: the distal pad's surface in front of the link's axis.
        distal_pad_centre_m: the distal pad's centre along the link.
        finger_half_width_m: half the fingers' width across the facing.
        proximal_back_m, proximal_pad_offset_m: the proximal link's extent across its axis:
            its back and its pad's surface.
        distal_back_m: the distal link's back behind its axis, along the facing.
        knuckle_radius_m: the knuckle (base rotation housing) radius.
        palm_radius_m: the palm housing's radius, down to the finger bases.
        joint_limit_rad: the bending joints' range.
    """

    fingers: tuple[str, ...]
    bases_m: np.ndarray
    facings: np.ndarray
    spread_signs: tuple[int, ...]
    base_radius_m: float
    base_depth_m: float
    knuckle_depth_m: float
    proximal_length_m: float
    distal_length_m: float
    distal_pad_offset_m: float
    distal_pad_centre_m: float
    finger_half_width_m: float
    proximal_back_m: float
    proximal_pad_offset_m: float
    distal_back_m: float
    knuckle_radius_m: float
    palm_radius_m: float
    joint_limit_rad: float

    @classmethod
    def of(cls, geometry: HandGeometry | None, hand: str = "") -> FingerKinematics:
        """The kinematics of a hand whose :class:`~pipeline.types.HandGeometry` has
        turn-and-bend fingers alike in their links, one of them with a fixed base; one
        object per geometry (its cached profiles are the planner's).

        Raises:
            ConfigError: the hand (named ``hand``) has no such fingers.
        """
        return _kinematics(geometry, hand)

    @classmethod
    def _read(cls, geometry: HandGeometry | None, hand: str) -> FingerKinematics:
        fingers = geometry.bending if geometry is not None else ()
        links = {_links(finger) for finger in fingers}
        fixed = [finger for finger in fingers if finger.spread_sign == 0]
        if not fingers or len(links) != 1 or len(fixed) != 1:
            raise ConfigError(
                f"hand '{hand}' has no turn-and-bend fingers alike in their links, one with a "
                f"fixed base (the SDH-2's kind; docs/hands.md)"
            )
        first = fingers[0]
        return cls(
            fingers=tuple(finger.name for finger in fingers),
            bases_m=np.array([finger.base_m for finger in fingers]),
            facings=np.array([finger.facing for finger in fingers]),
            spread_signs=tuple(finger.spread_sign for finger in fingers),
            base_radius_m=math.hypot(*fixed[0].base_m),
            base_depth_m=first.base_depth_m,
            knuckle_depth_m=first.base_depth_m + first.knuckle_length_m,
            proximal_length_m=first.proximal_length_m,
            distal_length_m=first.distal_length_m,
            distal_pad_offset_m=first.distal_pad_offset_m,
            distal_pad_centre_m=first.distal_pad_centre_m,
            finger_half_width_m=first.half_width_m,
            proximal_back_m=first.proximal_back_m,
            proximal_pad_offset_m=first.proximal_pad_offset_m,
            distal_back_m=first.distal_back_m,
            knuckle_radius_m=first.knuckle_radius_m,
            palm_radius_m=geometry.housing.radius_m,
            joint_limit_rad=first.bend_limit_rad,
        )

    def finger_facings(self, spread_rad: float) -> np.ndarray:
        """``(F, 2)`` unit facings in the palm's xy plane at base rotation ``spread_rad``:
        each finger's facing at spread 0 turned by its spread sign times ``spread_rad`` (the
        SDH-2's fingers 1 and 2 turn in opposite directions from facing the thumb, spread 0,
        to facing the palm axis, spread 60 deg; the thumb faces +x)."""
        facings = []
        for (x, y), sign in zip(self.facings, self.spread_signs, strict=True):
            if sign == 0:
                facings.append((x, y))
                continue
            c, s = math.cos(sign * spread_rad), math.sin(sign * spread_rad)
            facings.append((c * x - s * y, s * x + c * y))
        return np.array(facings, dtype=np.float64)

    def reach_m(self, alpha_rad: float | np.ndarray) -> float | np.ndarray:
        """Distal pad surface along the facing from the finger base (module doc)."""
        return self.proximal_length_m * np.sin(alpha_rad) + self.distal_pad_offset_m

    def alpha_for_reach(self, reach: float | np.ndarray) -> float | np.ndarray:
        """Proximal angle putting the distal pad surface at ``reach`` (NaN where out of range)."""
        sine = (
            np.asarray(reach, dtype=np.float64) - self.distal_pad_offset_m
        ) / self.proximal_length_m
        with np.errstate(invalid="ignore"):
            return np.where(np.abs(sine) <= 1.0, np.arcsin(np.clip(sine, -1.0, 1.0)), np.nan)

    def distal_pad_depth_m(self, alpha_rad: float | np.ndarray) -> float | np.ndarray:
        """Distal pad centre below the palm origin (module doc)."""
        return (
            self.knuckle_depth_m
            + self.proximal_length_m * np.cos(alpha_rad)
            + self.distal_pad_centre_m
        )

    def opening_for_alpha(self, alpha_rad: float) -> float:
        """The hand's ``opening_m`` for a proximal angle (module doc)."""
        return 2.0 * (self.base_radius_m - float(self.reach_m(alpha_rad)))

    def alpha_for_opening(self, opening_m: float) -> float:
        """Proximal angle (rad, negative = outward) giving ``opening_m``."""
        return math.asin(
            (self.base_radius_m - opening_m / 2.0 - self.distal_pad_offset_m)
            / self.proximal_length_m
        )

    def finger_profile(
        self, alpha_rad: float, step_m: float = 0.001
    ) -> tuple[np.ndarray, np.ndarray]:
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
        t_knuckle = np.arange(-self.knuckle_radius_m, self.knuckle_radius_m + step_m / 2, step_m)
        knuckle = np.column_stack([t_knuckle, np.full_like(t_knuckle, self.knuckle_depth_m)])
        # Proximal link with its pad: from the joint along (sin, cos) for its length.
        along, across = np.meshgrid(
            np.arange(0.0, self.proximal_length_m + step_m / 4, step_m / 2),
            np.arange(self.proximal_back_m, self.proximal_pad_offset_m + step_m / 4, step_m / 2),
        )
        proximal = np.column_stack(
            [
                along.ravel() * s + across.ravel() * c,
                self.knuckle_depth_m + along.ravel() * c - across.ravel() * s,
            ]
        )
        # Distal link, vertical, from its back face to the pad surface, down to the tip.
        joint_t = self.proximal_length_m * s
        tip_depth = self.knuckle_depth_m + self.proximal_length_m * c + self.distal_length_m
        t_distal = np.arange(
            joint_t + self.distal_back_m, joint_t + self.distal_pad_offset_m + step_m / 2, step_m
        )
        distal = np.column_stack([t_distal, np.full_like(t_distal, tip_depth)])
        samples = np.concatenate([knuckle, proximal, distal])
        grid = np.arange(samples[:, 0].min() - step_m, samples[:, 0].max() + 2 * step_m, step_m)
        depth = np.full(len(grid), -np.inf)
        index = np.clip(np.round((samples[:, 0] - grid[0]) / step_m).astype(int), 0, len(grid) - 1)
        np.maximum.at(depth, index, samples[:, 1])
        return grid, depth

    def closing_hits(
        self, t_m: np.ndarray, depth_m: np.ndarray, alphas_rad: Sequence[float], clearance_m: float
    ) -> np.ndarray:
        """``(K, N)``: which points, at distance ``t_m`` along a finger's facing from its base
        and ``depth_m`` below the palm (both ``(N,)``, within the finger's width), lie inside
        the finger's knuckle or proximal link with pad, grown by ``clearance_m``, at each of the
        ``K`` proximal angles ``alphas_rad``. The distal link is :meth:`distal_hits`'."""
        knuckle = (np.abs(t_m) <= self.knuckle_radius_m + clearance_m) & (
            (depth_m >= self.base_depth_m - clearance_m)
            & (depth_m <= self.knuckle_depth_m + clearance_m)
        )
        s = np.array([math.sin(alpha) for alpha in alphas_rad])[:, None]
        c = np.array([math.cos(alpha) for alpha in alphas_rad])[:, None]
        relative_d = depth_m - self.knuckle_depth_m
        along = t_m * s + relative_d * c
        across = t_m * c - relative_d * s
        proximal = (
            (along >= -clearance_m)
            & (along <= self.proximal_length_m + clearance_m)
            & (across >= self.proximal_back_m - clearance_m)
            & (across <= self.proximal_pad_offset_m + clearance_m)
        )
        return knuckle | proximal

    def distal_hits(
        self,
        t_m: np.ndarray,
        depth_m: np.ndarray,
        alphas_rad: Sequence[float],
        clearance_m: float,
        pad_rows_m: tuple[float, float],
        curve_start_m: float,
        front_allowance_m: float,
    ) -> np.ndarray:
        """``(K, N)``: which points (as in :meth:`closing_hits`) lie inside the finger's
        distal link, parallel to the palm axis, above or below its pad's taxel rows, at
        each of the ``K`` proximal angles ``alphas_rad``: behind its front by more than
        ``front_allowance_m``, within ``clearance_m`` of its back, its joint and its tip.

        ``pad_rows_m`` is where the taxel rows begin and end along the link from the
        distal joint (m). Between them the pad's predicted contact
        (:func:`~pipeline.planning.pad_contact.pad_coverage`) says where the finger stops;
        above them the link's front is the pad's surface; below them, at the tip, it is
        the pad's surface curving away from the object from ``curve_start_m`` (along the
        link from the joint) with the pad's radius (:data:`DISTAL_PAD_CURVE_RADIUS_M`).
        A surface that comes nearer there than the pad's contact, as a bowl's wall curving
        in under a finger inside it, or flaring out above a finger outside it, meets the
        link first, and the pad stays short of its contact."""
        s = np.array([math.sin(alpha) for alpha in alphas_rad])[:, None]
        c = np.array([math.cos(alpha) for alpha in alphas_rad])[:, None]
        # Below the distal joint (the proximal link's end) and forward of it.
        down = depth_m - self.knuckle_depth_m - self.proximal_length_m * c
        forward = t_m - self.proximal_length_m * s
        curved = np.clip(down - curve_start_m, 0.0, DISTAL_PAD_CURVE_RADIUS_M)
        recess = DISTAL_PAD_CURVE_RADIUS_M - np.sqrt(DISTAL_PAD_CURVE_RADIUS_M**2 - curved**2)
        top, bottom = pad_rows_m
        return (
            (
                (down >= -clearance_m) & (down < top)
                | (down > bottom) & (down <= self.distal_length_m + clearance_m)
            )
            & (forward >= self.distal_back_m - clearance_m)
            & (forward <= self.distal_pad_offset_m - recess - front_allowance_m)
        )


def _links(finger) -> tuple[float, ...]:
    """A finger's link dimensions, all but where its base is and how it turns."""
    return (
        finger.base_depth_m,
        finger.knuckle_length_m,
        finger.knuckle_radius_m,
        finger.proximal_length_m,
        finger.distal_length_m,
        finger.half_width_m,
        finger.proximal_back_m,
        finger.proximal_pad_offset_m,
        finger.distal_back_m,
        finger.distal_pad_offset_m,
        finger.distal_pad_centre_m,
        finger.bend_limit_rad,
    )


@functools.cache
def _kinematics(geometry: HandGeometry | None, hand: str) -> FingerKinematics:
    return FingerKinematics._read(geometry, hand)


def shipped() -> FingerKinematics:
    """The shipped SDH-2's kinematics (``robots/sdh2.urdf``)."""
    from pipeline.io.hand_urdf import hand_geometry

    return FingerKinematics.of(hand_geometry("sdh2.urdf"), "sdh")
