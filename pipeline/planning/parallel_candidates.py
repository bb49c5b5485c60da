"""Parallel-jaw grasp candidates: a jaw gripper's geometry (:class:`ParallelHand`) and one
candidate closing along a direction at a height (:func:`parallel_candidate`)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from pipeline.errors import ConfigError
from pipeline.planning.candidate import (
    BEYOND_CENTRE,
    BLIND_PAD_FACTOR,
    MIN_HITS,
    Candidate,
    CandidateCloud,
    CandidateSettings,
    candidate_score,
)
from pipeline.planning.grasp_geometry import hand_pose
from pipeline.planning.order_statistics import percentile
from pipeline.planning.pad_contact import PadTaxels, flat_pad_taxels, pad_coverage
from pipeline.types import GraspCandidate, GripperSpec, PadLayout


@dataclass(frozen=True)
class ParallelHand:
    """A parallel-jaw gripper's geometry for :func:`parallel_candidate` and for a jaw
    planner of your own, in metres, in the hand frame (z down the approach from the palm's
    flange, x the closing direction; docs/hands.md). :meth:`of` gathers it from a
    :class:`~pipeline.types.GripperSpec`.

    Attributes:
        pad: the front jaw's pad (its first pad): name, taxel rows along the finger and
            columns across it, pitch.
        pad_length_m, pad_width_m: the pad's extent along its rows and across them, its
            bare edges beyond the taxels included.
        aperture_m: the widest opening between the pads' surfaces.
        palm_to_pad_centre_m: how far the pads' centres lie below the palm's origin: a
            palm at height ``z`` puts them at ``z - palm_to_pad_centre_m``.
        pad_centre_to_fingertip_m: how far the finger carrying a pad reaches below the
            pad's centre.
        finger_recess_m: how far the finger's face stands behind the pad's surface.
        jaw_half_width_m: half the jaws' widest extent across the closing direction (y).
        housing_half_length_m: half the housing's extent along the closing direction.
        housing_half_width_m: half the housing's extent across it.
        housing_depth_m: how far the housing reaches below the palm's origin.
    """

    pad: PadLayout
    pad_length_m: float
    pad_width_m: float
    aperture_m: float
    palm_to_pad_centre_m: float
    pad_centre_to_fingertip_m: float
    finger_recess_m: float
    jaw_half_width_m: float
    housing_half_length_m: float
    housing_half_width_m: float
    housing_depth_m: float

    @classmethod
    def of(cls, gripper: GripperSpec, planner: str) -> ParallelHand:
        """The geometry of ``gripper``'s front jaw (its first pad) and housing, from its
        :attr:`~pipeline.types.GripperSpec.geometry` (the hand's URDF).

        Raises:
            ConfigError: ``gripper`` has no URDF geometry or no jaws on prismatic joints,
                or its pads hang no lower than its housing (named with ``planner``).
        """
        geometry = gripper.geometry
        if geometry is None or geometry.jaw_travel_m <= 0.0:
            raise ConfigError(
                f"planner '{planner}' needs a parallel gripper read from its URDF, but hand "
                f"'{gripper.name}' has no jaw geometry (GripperSpec.geometry; docs/hands.md)"
            )
        pad = gripper.pads[0]
        mount = geometry.pad(pad.name)
        housing = geometry.housing
        if housing.depth_m >= mount.centre_m[2]:
            raise ConfigError(
                f"planner '{planner}': hand '{gripper.name}' ({geometry.urdf}) has its pad "
                f"centres {mount.centre_m[2]:.4f} m below the palm, inside the housing "
                f"({housing.depth_m:.4f} m deep)"
            )
        return cls(
            pad=pad,
            pad_length_m=mount.length_m,
            pad_width_m=mount.width_m,
            aperture_m=gripper.max_aperture_m,
            palm_to_pad_centre_m=mount.centre_m[2],
            pad_centre_to_fingertip_m=mount.centre_to_fingertip_m,
            finger_recess_m=mount.recess_m,
            jaw_half_width_m=geometry.jaw_half_width_m,
            housing_half_length_m=housing.half_length_m,
            housing_half_width_m=housing.half_width_m,
            housing_depth_m=housing.depth_m,
        )


def front_jaw_gap(
    aperture_m: float,
    width_m: float,
    descent_m: float,
    jaw_clearance_m: float,
    back_margin_m: float,
) -> float | None:
    """Where the open jaws stand around an object ``width_m`` wide between their paths:
    the front jaw's gap before the visible front (m), the back jaw taking the rest of the
    aperture; None when they cannot both descend ``descent_m`` clear of it.

    The back jaw keeps ``back_margin_m`` beyond its clearance where the room allows (the
    back is the mirror plane's guess, and a mirrored model is often a few millimetres
    thinner than the object) and the front gap is ``jaw_clearance_m``, or half of what is
    left when less is. An object too wide for the margin is still grasped, the room split
    evenly between the jaws: neither lands on it when the model is off either way by less
    than half the room. Both jaws close towards the hand's centre, each at most half the
    aperture, so before a narrow object the front gap grows until the back jaw still
    reaches the back (placed by the front alone it would close on nothing: contact on one
    side only).
    """
    room_m = aperture_m - width_m
    if room_m < 2.0 * descent_m:
        return None
    if room_m - back_margin_m >= 2.0 * descent_m:
        gap_m = min(jaw_clearance_m, (room_m - back_margin_m) / 2.0)
    else:
        gap_m = room_m / 2.0
    reach_m = aperture_m / 2.0 - descent_m
    return max(gap_m, room_m - reach_m)


def parallel_candidate(
    cloud: CandidateCloud,
    centre_m: np.ndarray,
    direction: np.ndarray,
    angle_rad: float,
    height_m: float,
    hand: ParallelHand,
    settings: CandidateSettings,
    *,
    jaw_clearance_m: float,
    back_margin_m: float,
) -> Candidate:
    # A candidate's pose and hand, and its feasibility checks in order, each using the
    # geometry the one before computed: split, every piece would take these back.
    """A parallel-jaw grasp closing along ``direction`` (front to back) through ``centre_m``
    with the pad centres at ``height_m``.

    Both jaws descend clear of every point above the fingertips between their paths, the
    front jaw before the visible surface there and the back jaw behind the completed back,
    as far as :func:`front_jaw_gap` puts them; the surface between them must enclose
    ``centre_m``, and the front pad must stop before it. Where the model has no back under
    the back pad, that pad would pass the centre and meet the front wall from inside: its
    contact is unknown, reported as 0, and the grasp keeps :data:`BLIND_PAD_FACTOR` of the
    score the front pad's contact gives. The housing must pass above the object's top.
    """
    s = settings
    lateral = np.array([-direction[1], direction[0], 0.0])
    fingertip_z = height_m - hand.pad_centre_to_fingertip_m
    if s.below_clearance(fingertip_z):
        return Candidate.rejected(angle_rad, height_m, 0.0, "fingertips below the table clearance")

    def column(visible: bool) -> np.ndarray:
        """Where the points between the jaws' paths above the fingertips lie along
        ``direction`` (lowest first)."""
        across = cloud.offsets_above(centre_m, lateral, fingertip_z, visible=visible)
        along = cloud.offsets_above(_ORIGIN, direction, fingertip_z, visible=visible)
        return along.compress(np.abs(across) <= hand.jaw_half_width_m)

    front_along, all_along = column(visible=True), column(visible=False)
    if len(front_along) == 0:
        return Candidate.rejected(angle_rad, height_m, 0.0, "no visible surface between the jaws")
    front = percentile(front_along, 2.0)
    back = percentile(all_along, 98.0)
    if not front < centre_m @ direction < back:
        # Where the completed model has a gap (a thin-walled object's unseen side), the
        # column may hold one wall only: the jaws would pinch it, not close around the object.
        return Candidate.rejected(
            angle_rad, height_m, 0.0, "the jaws would close on one wall, not around the object"
        )
    width = back - front
    front_gap = front_jaw_gap(
        hand.aperture_m, width, s.descent_clearance_m, jaw_clearance_m, back_margin_m
    )
    if front_gap is None:
        return Candidate.rejected(
            angle_rad,
            height_m,
            0.0,
            f"{width * 1e3:.0f} mm wide between the jaws' paths, aperture "
            f"{hand.aperture_m * 1e3:.0f} mm",
        )
    front_pad = front - front_gap
    middle = front_pad + hand.aperture_m / 2.0
    position = centre_m + (middle - centre_m @ direction) * direction
    position[2] = height_m + hand.palm_to_pad_centre_m
    housing_bottom = position[2] - hand.housing_depth_m
    below_housing = cloud.above(housing_bottom - s.descent_clearance_m)
    offset = below_housing - position
    under_housing = (
        np.abs(offset @ direction) <= hand.housing_half_length_m + s.descent_clearance_m
    ) & (np.abs(offset @ lateral) <= hand.housing_half_width_m + s.descent_clearance_m)
    if np.count_nonzero(under_housing) >= MIN_HITS:
        return Candidate.rejected(
            angle_rad, height_m, 0.0, "the housing would hit the object's top"
        )

    contacts = []
    jaw = _jaw_taxels(hand, height_m)
    for seen, sign in ((True, 1.0), (False, -1.0)):
        side = "front" if sign > 0 else "back"
        # Only the points before the jaw's face, its bare cells included, can touch it.
        points = cloud.slab(*jaw.z_range_m, visible=seen)
        # Beyond the pad's sides the finger stands back: its face there meets nothing the
        # pad's edges do not meet first.
        before = np.abs((points - centre_m) @ lateral) <= hand.pad_width_m / 2.0
        points = points.compress(before, axis=0)
        contact = pad_coverage(points, position, sign * direction, jaw, s.touch_tolerance_m)
        if contact is None:
            taxels = _flat_taxels(hand.pad, height_m)
            if pad_coverage(points, position, sign * direction, taxels, s.touch_tolerance_m):
                # The taxels alone would touch: the jaw's bare part below them meets the
                # object first (a shoulder, or a lying cylinder's widest line).
                reason = f"the {side} finger meets the object before its pad"
            else:
                reason = f"no surface before the {side} pad"
            return Candidate.rejected(angle_rad, height_m, 0.0, reason)
        contacts.append(contact)
    if not contacts[0].stops_before(centre_m, direction):
        return Candidate.rejected(angle_rad, height_m, 0.0, BEYOND_CENTRE)
    tipping = (height_m - s.table_height_m) / cloud.footprint_half_m(direction)
    if contacts[1].stops_before(centre_m, -direction):
        coverages = tuple(c.quality for c in contacts)
        score = candidate_score(coverages, angle_rad, tipping, s.tipping_weight)
    else:
        # The model has no back under the back pad: where the jaws stand does not depend on
        # it (the column's extent places them), but what the pad would meet is unknown.
        coverages = (contacts[0].quality, 0.0)
        score = BLIND_PAD_FACTOR * candidate_score(
            coverages[:1], angle_rad, tipping, s.tipping_weight
        )
    return Candidate(
        GraspCandidate(
            closing_angle_deg=math.degrees(angle_rad),
            height_m=height_m,
            spread_deg=0.0,
            width_m=width,
            contact_coverage=coverages,
            tipping_ratio=tipping,
            score=score,
            feasible=True,
        ),
        T_robot_hand=hand_pose(position, direction),
        opening_m=hand.aperture_m,
        predicted_contacts=contacts[0].points,
    )


#: Offsets from it along an axis are the points' own products with the axis.
_ORIGIN = np.zeros(3)


@functools.lru_cache(maxsize=64)
def _flat_taxels(pad: PadLayout, height_m: float) -> PadTaxels:
    """:func:`flat_pad_taxels`, once per pad and height."""
    return flat_pad_taxels(pad, height_m)


@functools.lru_cache(maxsize=64)
def _jaw_taxels(hand: ParallelHand, height_m: float) -> PadTaxels:
    """A jaw's face at pad height ``height_m``: the pad's taxels, a bare column beside them
    on either side (the pad's side edges), and bare rows below them down to the fingertip,
    all as far apart as the taxels (the lowest row ends at the fingertip). A bare row is
    flush with the pad's surface where its cells overlap the pad (its lower edge beyond
    the taxels) and ``finger_recess_m`` behind it below. A jaw closing on a lying
    cylinder, across it or obliquely, or on a stepped side meets it with a bare part where
    the surface stands nearer beside or below the taxels: those cells stop the jaw but
    sense nothing (:attr:`PadTaxels.senses`). The points given must lie within the pad's
    width."""
    taxels = _flat_taxels(hand.pad, height_m)
    pitch = taxels.pitch_m
    fingertip_z = height_m - hand.pad_centre_to_fingertip_m
    lowest = float(taxels.row_z.min())
    bare_z = np.arange(lowest - pitch, fingertip_z + pitch / 2.0, -pitch)
    if (bare_z[-1] if len(bare_z) else lowest) - pitch / 2.0 > fingertip_z:
        bare_z = np.append(bare_z, fingertip_z + pitch / 2.0)
    pad_bottom_z = height_m - hand.pad_length_m / 2.0
    senses = np.zeros((len(taxels.row_z) + len(bare_z), len(taxels.col_u) + 2), dtype=bool)
    senses[: len(taxels.row_z), 1:-1] = True
    return PadTaxels(
        np.concatenate([[taxels.col_u[0] - pitch], taxels.col_u, [taxels.col_u[-1] + pitch]]),
        np.concatenate([taxels.row_z, bare_z]),
        np.concatenate(
            [
                taxels.row_recess,
                np.where(bare_z + pitch / 2.0 > pad_bottom_z, 0.0, hand.finger_recess_m),
            ]
        ),
        pitch,
        senses,
    )
