"""SDH-2 grasp candidates: one candidate at a pre-shape (base rotation, :data:`SDH_SPREADS`),
closing direction and pad height (:func:`sdh_candidate`; many at once,
:func:`sdh_candidates`), with the fingers' predicted contacts, the pre-shape search and the
closing check it needs."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import ConfigError
from pipeline.planning.candidate import (
    BEYOND_CENTRE,
    MIN_HITS,
    Candidate,
    CandidateCloud,
    CandidateSettings,
    candidate_score,
)
from pipeline.planning.grasp_geometry import hand_pose
from pipeline.planning.order_statistics import percentile, percentiles
from pipeline.planning.pad_contact import (
    LAYER_M,
    PadContact,
    PadTaxels,
    pad_coverages,
    sdh_distal_taxels,
    sdh_flat_part_edge_m,
)
from pipeline.planning.sdh_geometry import FingerKinematics
from pipeline.types import GraspCandidate, GripperSpec, PadLayout

SDH_SPREADS = (math.radians(60.0), 0.0)
"""SDH-2 pre-shapes every grasp is tried with, as base rotations: at 60 deg the fingers face the
palm axis (a tripod); at 0 fingers 1 and 2 face the thumb (where the object's centre sits:
:meth:`SdhHand.centre_offset_m`)."""
PINCH_SPREAD_RAD = math.pi / 2.0
"""The pinch: at 90 deg fingers 1 and 2 face each other across the palm and close on the object
from two sides, its centre on the line between their bases, while the thumb closes on a third
side. Tried where the object is too narrow across for fingers 1 and 2 facing the thumb."""
TOO_NARROW = "too narrow for fingers facing the thumb"
"""Why :func:`sdh_candidate` rejects a grasp at spread 0 that the pinch may take instead."""
CLOSING_HIT = "a proximal link would hit the object while closing"
"""Why :func:`sdh_candidate` rejects a grasp whose knuckle or proximal link meets the seen
cloud on the fingers' way from the pre-shape to their contacts: checked at the contacts
before the pre-shape search (a link there rejects every pre-shape), the way to them after
it."""
DISTAL_HIT = "a distal link would meet the object before its pad while closing"
"""Why :func:`sdh_candidate` rejects a grasp whose distal link (its tip below the pad, its
back, its curved pad's recessed end) meets the seen cloud on the way to the pad's contact:
a surface nearer below the pad than the pad's own, as a bowl's wall curving in under a
finger inside it (:meth:`FingerKinematics.distal_hits`); checked, as :data:`CLOSING_HIT`,
at the contacts and then on the way to them."""
#: Steps of the pre-shape search: proximal angles tried below the contact angle (rad).
_OPEN_STEP_RAD = math.radians(3.0)


@dataclass(frozen=True, eq=False)
class SdhHand:
    """An SDH-2-like hand for :func:`sdh_candidate`: its finger kinematics, its distal
    pads' layout and its widest opening (m)."""

    kinematics: FingerKinematics
    pad: PadLayout
    aperture_m: float

    @classmethod
    def of(cls, gripper: GripperSpec, planner: str) -> SdhHand:
        """The hand ``gripper`` as its :attr:`~pipeline.types.GripperSpec.geometry` (its
        URDF) describes it; the distal pads are the ones that close
        (:attr:`~pipeline.types.GripperSpec.closing`).

        Raises:
            ConfigError: ``gripper`` has no turn-and-bend fingers of the SDH-2's kind
                (named with ``planner``).
        """
        try:
            kinematics = FingerKinematics.of(gripper.geometry, gripper.name)
        except ConfigError as error:
            raise ConfigError(f"planner '{planner}': {error}") from None
        layouts = {pad.name: pad for pad in gripper.pads}
        return cls(kinematics, layouts[gripper.closing[0].pad], gripper.max_aperture_m)

    def centre_offset_m(self, spread_rad: float) -> float:
        """Where the object's centre sits on the palm's x axis (m) at the pre-shape
        ``spread_rad``: on the palm axis for the tripod, midway between the fixed finger's
        (the thumb's) base and the turning fingers' at spread 0, on the line between the
        turning fingers' bases for the pinch."""
        kinematics = self.kinematics
        turning = [i for i, sign in enumerate(kinematics.spread_signs) if sign != 0]
        fixed = kinematics.spread_signs.index(0)
        if spread_rad == 0.0:
            return (kinematics.bases_m[turning[0], 0] + kinematics.bases_m[fixed, 0]) / 2.0
        if spread_rad == PINCH_SPREAD_RAD:
            return float(kinematics.bases_m[turning[0], 0])
        return 0.0

    def distal_pad_m(self) -> tuple[tuple[float, float], float]:
        """Where the distal pad's taxel rows begin and end, and where its curved tip
        begins, along the distal link from its joint (m): what
        :meth:`FingerKinematics.distal_hits` takes."""
        centre = self.kinematics.distal_pad_centre_m
        low, high = _distal_taxels(self.pad, 0.0).z_range_m
        return (centre - high, centre - low), centre + sdh_flat_part_edge_m(self.pad)

    def turning_lateral_m(self) -> float:
        """How far the turning fingers' bases lie either side of the palm's x axis (m)."""
        turning = self.kinematics.spread_signs.index(1)
        return float(abs(self.kinematics.bases_m[turning, 1]))

    def parallel_finger_offsets_m(self) -> tuple[float, ...]:
        """The fingers' bases along the palm's y axis (m), the fixed finger (the thumb)
        first: where their pads meet the object at spread 0, fingers 1 and 2 facing it."""
        signs = self.kinematics.spread_signs
        order = [signs.index(0)] + [i for i, sign in enumerate(signs) if sign != 0]
        return tuple(float(self.kinematics.bases_m[i, 1]) for i in order)


def sdh_candidate(
    cloud: CandidateCloud,
    centre_m: np.ndarray,
    direction: np.ndarray,
    angle_rad: float,
    height_m: float,
    spread_rad: float,
    sdh: SdhHand,
    settings: CandidateSettings,
) -> Candidate:
    # A candidate's pose and hand, and its feasibility checks in order, each using the
    # geometry the one before computed: split, every piece would take these back.
    """An SDH-2 grasp at base rotation ``spread_rad`` (a key of :data:`SDH_SPREADS`, or
    :data:`PINCH_SPREAD_RAD`), the palm's x axis along ``direction`` (thumb on the front
    side), distal pad centres at ``height_m``. Fingers 1 and 2 facing the thumb (spread 0)
    need the object as wide as their two pads across the closing line.

    Each finger's contact angle is the proximal angle at which its distal pad (distal link
    parallel to the palm axis) touches the completed cloud (visible and mirrored)
    (:func:`pad_coverage`), before ``centre_m`` on its way (past it, the model has no
    surface on the finger's side there, and the pad would meet the far side from inside);
    the palm height puts the pads' centres at ``height_m`` at those angles. The pre-shape is
    the most closed common proximal angle, at least 3 deg before the earliest contact, at
    which every finger, the knuckles and the palm descend clear of the cloud
    (:meth:`FingerKinematics.finger_profile`); ``opening_m`` is that pre-shape's opening.
    From there to its contact no finger's knuckle or proximal link may meet the seen cloud
    (:meth:`FingerKinematics.closing_hits`), nor its distal link anywhere but at its pad's
    surface (:meth:`FingerKinematics.distal_hits`); at the contact angles that is checked
    before the pre-shape search, and a grasp rejected there is rejected for its closing
    (:data:`CLOSING_HIT`, :data:`DISTAL_HIT`) whatever its pre-shape would have been. The
    hand's shape is ``sdh``'s.
    """
    return sdh_candidates(
        cloud, centre_m, [(angle_rad, direction, height_m)], spread_rad, sdh, settings
    )[0]


@dataclass
class _Hand:
    """One SDH-2 grasp on its way through :func:`sdh_candidates`' checks: its pose, the
    hand's axes and fingers (robot xy), and the fingers' contacts once found; ``verdict``
    the rejected candidate once a check rejects it."""

    angle_rad: float
    height_m: float
    x_hand: np.ndarray
    y_hand: np.ndarray
    palm_xy: np.ndarray
    rotation: np.ndarray
    facings: np.ndarray
    taxels: PadTaxels
    in_band: np.ndarray
    bases: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    contacts: list[PadContact] = field(default_factory=list)
    alphas: list[float] = field(default_factory=list)
    verdict: Candidate | None = None


def sdh_candidates(
    cloud: CandidateCloud,
    centre_m: np.ndarray,
    poses: list[tuple[float, np.ndarray, float]],
    spread_rad: float,
    sdh: SdhHand,
    settings: CandidateSettings,
    touched: CandidateCloud | None = None,
    beyond_m: float = 0.0,
) -> list[Candidate]:
    """:func:`sdh_candidate` at each of ``poses`` (closing angle, direction, pad height),
    with the fingers' pad contacts of every pose at one height predicted together (one
    pass over the points at the pads' rows, :func:`pad_coverages`).

    A pinch across a wall (:mod:`pipeline.planning.rim`) changes two things: the pads meet
    the surface of ``touched`` (default ``cloud``: the pinch leaves out the object's far
    side, which lies behind the finger inside it), and a pad may stop up to ``beyond_m``
    past ``centre_m`` (the wall's hidden face); every other check is on ``cloud``."""
    s = settings
    touched = cloud if touched is None else touched
    kinematics, pad = sdh.kinematics, sdh.pad
    centre_offset = sdh.centre_offset_m(spread_rad)
    facings = kinematics.finger_facings(spread_rad)
    hands = []
    for angle_rad, direction, height_m in poses:
        x_hand = np.array([direction[0], direction[1], 0.0])
        y_hand = np.array([direction[1], -direction[0], 0.0])
        rotation = np.column_stack([x_hand[:2], y_hand[:2]])
        hand = _Hand(
            angle_rad,
            height_m,
            x_hand,
            y_hand,
            centre_m - centre_offset * x_hand,
            rotation,
            facings @ rotation.T,
            _distal_taxels(pad, height_m),
            cloud.band(height_m, pad.rows * pad.pitch_m / 2.0),
        )
        hands.append(hand)
        if spread_rad == 0.0:
            # Fingers 1 and 2 facing the thumb meet the back either side of the closing
            # line: the object must be wide enough there for both their pads.
            across = hand.in_band @ y_hand
            span = sdh.turning_lateral_m() + pad.cols * pad.pitch_m / 2.0
            low, high = percentiles(across, (2.0, 98.0))
            if len(across) == 0 or max(low, high) - min(low, high) < 2.0 * span:
                hand.verdict = Candidate.rejected(angle_rad, height_m, spread_rad, TOO_NARROW)
    # Fingers meet an object off the palm axis inclined, so the palm is moved once, onto
    # the centre of the contacts predicted from the first guess.
    for attempt in range(2):
        by_height: dict[float, list[_Hand]] = {}
        for hand in hands:
            if hand.verdict is None:
                by_height.setdefault(hand.height_m, []).append(hand)
        for group in by_height.values():
            taxels = group[0].taxels
            for hand in group:
                hand.bases = hand.palm_xy[:2] + kinematics.bases_m @ hand.rotation.T
            # Only the points at the pads' rows can touch them.
            found = _fingers_contacts(
                kinematics,
                touched.slab(*taxels.z_range_m),
                [hand.bases for hand in group],
                [hand.facings for hand in group],
                taxels,
                s.touch_tolerance_m,
            )
            for hand, contacts in zip(group, found, strict=True):
                if isinstance(contacts, str):
                    hand.verdict = Candidate.rejected(
                        hand.angle_rad, hand.height_m, spread_rad, contacts
                    )
                    continue
                hand.contacts, hand.alphas = contacts
                if attempt == 0:
                    hand.palm_xy = _contact_centre(
                        hand.contacts, hand.x_hand, hand.y_hand, spread_rad
                    ) - (centre_offset * hand.x_hand)
    distal_pad = sdh.distal_pad_m()
    return [
        hand.verdict
        if hand.verdict is not None
        else _checked(cloud, centre_m, hand, spread_rad, sdh, s, beyond_m, distal_pad)
        for hand in hands
    ]


def _checked(
    cloud: CandidateCloud,
    centre_m: np.ndarray,
    hand: _Hand,
    spread_rad: float,
    sdh: SdhHand,
    s: CandidateSettings,
    beyond_m: float,
    distal_pad: tuple[tuple[float, float], float],
) -> Candidate:
    """The checks of :func:`sdh_candidate` after the fingers' contacts are found (a pad
    may stop ``beyond_m`` past ``centre_m``; ``distal_pad``: :meth:`SdhHand.distal_pad_m`),
    and the feasible candidate's score and plan."""
    angle_rad, height_m = hand.angle_rad, hand.height_m
    x_hand, palm_xy, in_band = hand.x_hand, hand.palm_xy, hand.in_band
    bases, facings, contacts, alphas = hand.bases, hand.facings, hand.contacts, hand.alphas
    k = sdh.kinematics
    along = np.zeros((len(facings), 3))
    along[:, :2] = facings
    if not all(
        contact.stops_before(centre_m + beyond_m * facing, facing)
        for contact, facing in zip(contacts, along, strict=True)
    ):
        return Candidate.rejected(angle_rad, height_m, spread_rad, BEYOND_CENTRE)
    palm_z = height_m + float(np.mean(k.distal_pad_depth_m(np.array(alphas))))
    below_palm = cloud.above(palm_z - k.base_depth_m - s.descent_clearance_m - _MARGIN_M)
    radial = np.hypot(*(below_palm[:, :2] - palm_xy[:2]).T)
    palm_hit = (radial <= k.palm_radius_m + s.descent_clearance_m) & (
        palm_z - below_palm[:, 2] <= k.base_depth_m + s.descent_clearance_m
    )
    if np.count_nonzero(palm_hit) >= MIN_HITS:
        return Candidate.rejected(
            angle_rad, height_m, spread_rad, "the palm would hit the object's top"
        )
    # Points deeper than the proximal link reaches from its joint are never hit closing.
    reach = _closing_reach_m(k, s.touch_tolerance_m)
    closing = _closing_corridors(
        k, cloud, palm_z - k.knuckle_depth_m - reach - _MARGIN_M, bases, facings, palm_z, s
    )
    # Every closing ends at the contact angles, whatever the pre-shape: a link that meets
    # the cloud there rejects the grasp before the pre-shape search.
    hit = _closing_collides(k, closing, [[alpha] for alpha in alphas], s, distal_pad)
    if hit is not None:
        return Candidate.rejected(angle_rad, height_m, spread_rad, hit)
    open_alpha = _clear_preshape(k, cloud, bases, facings, palm_z, min(alphas), s)
    if open_alpha is None:
        return Candidate.rejected(
            angle_rad, height_m, spread_rad, "the fingers cannot open around the object"
        )
    opening = k.opening_for_alpha(open_alpha)
    if opening > sdh.aperture_m + 1e-9:
        return Candidate.rejected(angle_rad, height_m, spread_rad, "wider than the hand opens")
    on_the_way = [list(np.arange(open_alpha, contact, _OPEN_STEP_RAD)) for contact in alphas]
    hit = _closing_collides(k, closing, on_the_way, s, distal_pad)
    if hit is not None:
        return Candidate.rejected(angle_rad, height_m, spread_rad, hit)
    # Closing from the pre-shape, the fingertips are lowest where the proximal links pass
    # closest to vertical.
    steepest = 0.0 if open_alpha <= 0.0 <= max(alphas) else min(abs(open_alpha), abs(max(alphas)))
    lowest_tip = palm_z - (
        k.knuckle_depth_m + k.proximal_length_m * math.cos(steepest) + k.distal_length_m
    )
    if s.below_clearance(lowest_tip):
        return Candidate.rejected(
            angle_rad, height_m, spread_rad, "fingertips below the table clearance"
        )
    coverages = tuple(c.quality for c in contacts)
    tipping = (height_m - s.table_height_m) / cloud.footprint_half_m(x_hand)
    score = candidate_score(coverages, angle_rad, tipping, s.tipping_weight)
    pad_top, joint = _pad_top_and_joint(k, hand.taxels)
    above_pads = cloud.above(pad_top)
    if any(
        _top_edge_above_pad(
            k, above_pads, np.append(base, 0.0), np.append(facing, 0.0), pad_top, joint, c
        )
        for base, facing, c in zip(bases, facings, contacts, strict=True)
    ):
        score *= _EDGE_PENALTY
    width = float(np.ptp(in_band @ x_hand)) if len(in_band) else math.nan
    position = np.array([palm_xy[0], palm_xy[1], palm_z])
    order = (2, 0, 1)  # thumb, finger 1, finger 2
    return Candidate(
        GraspCandidate(
            closing_angle_deg=math.degrees(angle_rad),
            height_m=height_m,
            spread_deg=math.degrees(spread_rad),
            width_m=width,
            contact_coverage=tuple(coverages[i] for i in order),
            tipping_ratio=tipping,
            score=score,
            feasible=True,
        ),
        T_robot_hand=hand_pose(position, x_hand),
        opening_m=opening,
        spread_rad=spread_rad,
        predicted_contacts=np.concatenate([contacts[i].points for i in order]),
    )


def _fingers_contacts(
    kinematics: FingerKinematics,
    points: np.ndarray,
    bases: list[np.ndarray],
    facings: list[np.ndarray],
    taxels: PadTaxels,
    tolerance_m: float,
) -> list[tuple[list[PadContact], list[float]] | str]:
    """Each hand's (its finger bases and facings, ``(3, 2)`` each) fingers' predicted
    distal pad contacts with ``points`` (the completed cloud, or the part of it at the
    pads' rows) and their proximal angles there, or why a finger finds none; every pad of
    every hand in one :func:`pad_coverages`."""
    origins = np.column_stack([np.concatenate(bases), np.zeros(3 * len(bases))])
    directions = np.column_stack([np.concatenate(facings), np.zeros(3 * len(facings))])
    found = pad_coverages(points, origins, directions, taxels, tolerance_m)
    # Every finger's angle in one call: the arcsine is taken element by element alike.
    reaches = [
        math.nan if c is None else c.touch_m - o @ d
        for o, d, c in zip(origins, directions, found, strict=True)
    ]
    angles = kinematics.alpha_for_reach(np.array(reaches)).tolist()
    return [
        _finger_angles(kinematics, found[first : first + 3], angles[first : first + 3])
        for first in range(0, len(found), 3)
    ]


def _finger_angles(
    kinematics: FingerKinematics, contacts: list[PadContact | None], angles: list[float]
) -> tuple[list[PadContact], list[float]] | str:
    """One hand's fingers' contacts and proximal angles (rad), or why a finger finds none
    (the first such finger's reason)."""
    for finger, contact, alpha in zip(kinematics.fingers, contacts, angles, strict=True):
        if contact is None:
            return f"{finger} meets no surface"
        if not abs(alpha) < kinematics.joint_limit_rad:
            return f"{finger} cannot reach the surface"
    return list(contacts), angles


def _contact_centre(
    contacts: list[PadContact], x_hand: np.ndarray, y_hand: np.ndarray, spread_rad: float
) -> np.ndarray:
    """Where the object's centre lies among the fingers' predicted contacts (f1, f2,
    thumb), robot xy with z 0: midway between the thumb's contact and the fingers' along
    the palm's x axis, between finger 1's and finger 2's across it (spread 0); midway
    between finger 1's and finger 2's (the pinch); or the circumcentre of the three
    contacts (fingers facing the palm axis)."""
    # Each contact's mean point (``mean``'s sum and division, without its checks).
    points = np.array([c.points[:, :2].sum(axis=0) / len(c.points) for c in contacts])
    if spread_rad == 0.0:
        x = (points[:2].mean(axis=0) @ x_hand[:2] + points[2] @ x_hand[:2]) / 2.0
        y = points[:2].mean(axis=0) @ y_hand[:2]
        return np.append(x * x_hand[:2] + y * y_hand[:2], 0.0)
    if spread_rad == PINCH_SPREAD_RAD:
        return np.append(points[:2].mean(axis=0), 0.0)
    a, b, c = points
    d = 2.0 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
    if abs(d) < 1e-9:
        return np.append(points.mean(axis=0), 0.0)
    norms = (a @ a, b @ b, c @ c)
    ux = (norms[0] * (b[1] - c[1]) + norms[1] * (c[1] - a[1]) + norms[2] * (a[1] - b[1])) / d
    uy = (norms[0] * (c[0] - b[0]) + norms[1] * (a[0] - c[0]) + norms[2] * (b[0] - a[0])) / d
    return np.array([ux, uy, 0.0])


def _clear_preshape(
    kinematics: FingerKinematics,
    cloud: CandidateCloud,
    bases: np.ndarray,
    facings: np.ndarray,
    palm_z: float,
    contact_alpha: float,
    s: CandidateSettings,
) -> float | None:
    """The most closed proximal angle on a 3-deg grid, at least 3 deg before
    ``contact_alpha``, at which every finger descends clear of the completed cloud (the
    palm at height ``palm_z``); None when none does."""
    step = math.floor((contact_alpha - _OPEN_STEP_RAD) / _OPEN_STEP_RAD)
    steps = []
    while step * _OPEN_STEP_RAD > -kinematics.joint_limit_rad:
        steps.append(step)
        step -= 1
    # Points deeper below the palm than any profile reaches, or beside every profile's
    # grid, are never hit.
    deepest, t_low, t_high = _profile_bounds(kinematics, s.descent_clearance_m)
    corridors = _corridors(
        cloud,
        palm_z - deepest - _MARGIN_M,
        False,
        bases,
        facings,
        palm_z,
        kinematics.finger_half_width_m + s.descent_clearance_m,
        lambda t, _: (t >= t_low) & (t <= t_high),
    )
    # The corridors run from the deepest point up (``cloud.above``'s order): their last
    # points are the shallowest below the palm, the first any pre-shape sweeps. A pre-shape
    # that sweeps MIN_HITS of those is blocked whatever the rest; of the others, in order,
    # the first that sweeps fewer than MIN_HITS of all the points is the answer.
    for first in range(0, len(steps), _STEPS_AT_ONCE):
        chunk = tuple(steps[first : first + _STEPS_AT_ONCE])
        shallowest = [(t[-_SHALLOWEST:], d[-_SHALLOWEST:]) for t, d in corridors]
        hits = _profile_hits(kinematics, chunk, shallowest, s.descent_clearance_m)
        for k in np.flatnonzero(np.all(hits < MIN_HITS, axis=1)):
            hits = _profile_hits(kinematics, chunk[k : k + 1], corridors, s.descent_clearance_m)
            if np.all(hits < MIN_HITS):
                return chunk[k] * _OPEN_STEP_RAD
    return None


def _closing_corridors(
    kinematics: FingerKinematics,
    cloud: CandidateCloud,
    z_m: float,
    bases: np.ndarray,
    facings: np.ndarray,
    palm_z: float,
    s: CandidateSettings,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each finger's corridor (:func:`_corridors`) through the visible points above
    ``z_m``, grown by the touch tolerance, without the points farther from the proximal
    joint than any part of the finger reaches at any angle: what :func:`_closing_collides`
    tests. Only seen points count: the mirrored ones are where the plane guesses the back,
    too uncertain to veto a grasp on."""
    reach = _closing_reach_m(kinematics, s.touch_tolerance_m) + _MARGIN_M
    return _corridors(
        cloud,
        z_m,
        True,
        bases,
        facings,
        palm_z,
        kinematics.finger_half_width_m + s.touch_tolerance_m,
        lambda t, d: t * t + (d - kinematics.knuckle_depth_m) ** 2 <= reach * reach,
    )


def _closing_collides(
    kinematics: FingerKinematics,
    corridors: list[tuple[np.ndarray, np.ndarray]],
    alphas: list[list[float]],
    s: CandidateSettings,
    distal_pad_m: tuple[tuple[float, float], float],
) -> str | None:
    """Why a finger meets its corridor's points (:func:`_closing_corridors`) at one of its
    proximal ``alphas`` (rad, a list per finger), or None: its knuckle or proximal link
    (:data:`CLOSING_HIT`; on a tall object a low grasp swings the proximal links into its
    upper part), else its distal link short of its pad's contact (:data:`DISTAL_HIT`;
    ``distal_pad_m``: :meth:`SdhHand.distal_pad_m`). A closing is checked every 3 deg from
    the pre-shape and at the contact."""
    rows, curve_start = distal_pad_m
    # The pad's touch is the middle of the surface layer before each taxel (LAYER_M deep):
    # the same surface reaches up to half that layer nearer.
    distal = functools.partial(
        kinematics.distal_hits,
        pad_rows_m=rows,
        curve_start_m=curve_start,
        front_allowance_m=s.touch_tolerance_m + LAYER_M / 2.0,
    )
    for hits, reason in ((kinematics.closing_hits, CLOSING_HIT), (distal, DISTAL_HIT)):
        for (t, d), angles in zip(corridors, alphas, strict=True):
            if angles and _any_angle_hits(hits(t, d, angles, s.touch_tolerance_m)):
                return reason
    return None


def _any_angle_hits(hits: np.ndarray) -> bool:
    """Whether any angle's row of ``hits`` (``(K, N)``) holds :data:`MIN_HITS` points:
    a single angle's counted over the whole array, several angles' by a sum
    (``count_nonzero`` along an axis copies its input first)."""
    if len(hits) == 1:
        return np.count_nonzero(hits) >= MIN_HITS
    return bool(np.any(hits.sum(axis=1) >= MIN_HITS))


@functools.lru_cache(maxsize=16)
def _closing_reach_m(kinematics: FingerKinematics, clearance_m: float) -> float:
    """The farthest from the proximal joint a point inside the finger, grown by
    ``clearance_m`` (:meth:`FingerKinematics.closing_hits`,
    :meth:`FingerKinematics.distal_hits`), can lie (m), at any proximal angle."""
    k, c = kinematics, clearance_m
    thickest = max(abs(k.proximal_back_m - c), abs(k.proximal_pad_offset_m + c))
    link = math.hypot(k.proximal_length_m + c, thickest)
    depth = max(abs(k.base_depth_m - c - k.knuckle_depth_m), c)
    knuckle = math.hypot(k.knuckle_radius_m + c, depth)
    # The distal joint lies a proximal length from it; the distal link hangs below.
    distal = k.proximal_length_m + math.hypot(
        k.distal_length_m + c, max(abs(k.distal_back_m - c), abs(k.distal_pad_offset_m))
    )
    return max(link, knuckle, distal)


def _corridors(
    cloud: CandidateCloud,
    z_m: float,
    visible: bool,
    bases: np.ndarray,
    facings: np.ndarray,
    palm_z: float,
    half_width_m: float,
    keep: Callable[[np.ndarray, np.ndarray], np.ndarray],
) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each finger (base and facing, ``(F, 2)`` each), the points of
    ``cloud.above(z_m, visible=visible)`` within ``half_width_m`` of the line along its
    facing through its base that ``keep`` keeps (given every point's ``t`` and ``d``, a
    mask): their distance ``t`` along the facing from the base and their depth ``d``
    below the palm at ``palm_z`` (m), in the order of those points.

    The closing check's (``visible``) offsets come from the products a closing
    direction's candidates share (:meth:`CandidateCloud.along_above`): most candidates
    reach that check. The pre-shape search, on the completed cloud, which few reach,
    takes its own."""
    normals = facings[:, ::-1] * _TURN_LEFT
    points = cloud.above(z_m, visible=visible)
    # Every finger's offsets, ``(F, N)``.
    if visible:
        across = cloud.along_above(normals, z_m, visible=True)
        along = cloud.along_above(facings, z_m, visible=True)
    else:
        xy = points[:, :2].T
        across, along = normals @ xy, facings @ xy
    across = np.abs(across - np.sum(bases * normals, axis=1)[:, None])
    along = along - np.sum(bases * facings, axis=1)[:, None]
    depth = palm_z - points[:, 2]
    corridors = []
    for t, offset in zip(along, across, strict=True):
        # One selection for both tests: the points are selected once.
        near = (offset <= half_width_m) & keep(t, depth)
        corridors.append((t.compress(near), depth.compress(near)))
    return corridors


#: A horizontal unit ``(x, y)``, reversed and multiplied by this, turned 90 deg to its left.
_TURN_LEFT = np.array([-1.0, 1.0])
#: Resolution of the finger profiles the pre-shape search compares the cloud with (m).
_PROFILE_STEP_M = 0.001
#: Pre-shapes the search compares the cloud's shallowest points with at once: most are
#: found within a few.
_STEPS_AT_ONCE = 8
#: How many of each finger's shallowest points rule out a pre-shape before the rest are
#: compared with it.
_SHALLOWEST = 256
#: Slack of the cheap height bounds that select the points an exact test then checks (m).
_MARGIN_M = 1e-6


@functools.lru_cache(maxsize=256)
def _swept_profile(
    kinematics: FingerKinematics, step: int, clearance_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """The finger profile at proximal angle ``step`` x 3 deg, grown by ``clearance_m`` in
    both directions."""
    grid, depth = kinematics.finger_profile(step * _OPEN_STEP_RAD, _PROFILE_STEP_M)
    half = math.ceil(clearance_m / _PROFILE_STEP_M)
    # The greatest depth within ``half`` cells either side, the ends mirrored.
    padded = np.pad(depth, half, mode="symmetric")
    grown = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1).max(axis=1)
    return grid, grown + clearance_m


@functools.lru_cache(maxsize=16)
def _profile_bounds(kinematics: FingerKinematics, clearance_m: float) -> tuple[float, float, float]:
    """Over every pre-shape within the joint limits: the deepest any grown profile reaches
    below the palm, and the least and greatest distance along the facing a point may have
    and still fall on a profile's grid (m)."""
    limit = math.ceil(kinematics.joint_limit_rad / _OPEN_STEP_RAD)
    profiles = [_swept_profile(kinematics, step, clearance_m) for step in range(-limit, limit + 1)]
    return (
        max(float(reach.max()) for _, reach in profiles),
        min(float(grid[0]) for grid, _ in profiles) - _PROFILE_STEP_M,
        max(float(grid[-1]) for grid, _ in profiles) + _PROFILE_STEP_M,
    )


@functools.lru_cache(maxsize=1024)
def _profile_table(
    kinematics: FingerKinematics, steps: tuple[int, ...], clearance_m: float
) -> tuple[np.ndarray, ...]:
    """The grown profiles of ``steps`` (:func:`_swept_profile`) as arrays: each grid's
    first distance ``(K,)``, the reaches ``(K, longest + 2)``, each grid's cells from
    column 1 on and -inf before and after them (no part of the finger there), and the
    deepest reach of them all (0-d)."""
    profiles = [_swept_profile(kinematics, step, clearance_m) for step in steps]
    longest = max(len(grid) for grid, _ in profiles)
    reaches = np.full((len(steps), longest + 2), -np.inf)
    for row, (_, reach) in enumerate(profiles):
        reaches[row, 1 : len(reach) + 1] = reach
    return np.array([grid[0] for grid, _ in profiles]), reaches, np.max(reaches)


def _profile_hits(
    kinematics: FingerKinematics,
    steps: tuple[int, ...],
    corridors: list[tuple[np.ndarray, np.ndarray]],
    clearance_m: float,
) -> np.ndarray:
    """``(K, F)``: how many points of each finger's corridor (distances ``t`` along its
    facing and depths ``d`` below the palm, both ``(N_f,)``) each pre-shape of ``steps``
    sweeps on its descent."""
    starts, reaches, deepest = _profile_table(kinematics, steps, clearance_m)
    t = np.concatenate([t for t, _ in corridors])
    d = np.concatenate([d for _, d in corridors])
    # A point deeper than every profile reaches is hit by none.
    shallow = d <= deepest
    kept = np.concatenate([[0], np.cumsum(shallow)])
    ends = kept[np.cumsum([len(t) for t, _ in corridors])]
    t, d = t.compress(shallow), d.compress(shallow)
    index = np.round((t[None, :] - starts[:, None]) / _PROFILE_STEP_M).astype(int)
    # Cells before a grid's start read column 0 and after its end a later one: -inf.
    width = reaches.shape[1]
    cells = np.clip(index + 1, 0, width - 1) + width * np.arange(len(steps))[:, None]
    running = np.zeros((len(steps), len(t) + 1), dtype=np.int64)
    np.cumsum(d[None, :] <= reaches.take(cells), axis=1, out=running[:, 1:])
    return np.diff(running[:, np.concatenate([[0], ends])], axis=1)


#: How deep behind a pad's touch the surface counts as the side it closes on, looking for
#: that side's top edge (m).
_EDGE_DEPTH_M = 0.015
#: Score factor of a grasp with a top edge behind a distal link (:func:`_top_edge_above_pad`):
#: such a grasp is taken only where no other comes near, as on a box too tall for the pads
#: to reach clear of its top edge (docs/method.md §5 has what a quarter and a fiftieth did).
_EDGE_PENALTY = 0.1


@functools.lru_cache(maxsize=64)
def _distal_taxels(pad: PadLayout, height_m: float) -> PadTaxels:
    """:func:`sdh_distal_taxels`, once per pad and height."""
    return sdh_distal_taxels(pad, height_m)


def _pad_top_and_joint(kinematics: FingerKinematics, taxels: PadTaxels) -> tuple[float, float]:
    """The height of a distal pad's top row's upper edge and of its distal joint (m),
    the pad on a vertical distal link (for :func:`_top_edge_above_pad`)."""
    pad_top = float(taxels.row_z.max()) + taxels.pitch_m / 2.0
    joint = float(np.median(taxels.row_z)) + kinematics.distal_pad_centre_m  # the middle row
    return pad_top, joint


def _top_edge_above_pad(
    kinematics: FingerKinematics,
    points: np.ndarray,
    origin_m: np.ndarray,
    direction: np.ndarray,
    pad_top_m: float,
    joint_m: float,
    contact: PadContact,
) -> bool:
    """Whether the top edge of the side a distal pad closes on lies between the pad's top
    row's upper edge (``pad_top_m``) and the distal joint (``joint_m``), where the link
    stands 1 mm behind the pad's surface. A rim, lip or lid there is often a millimetre or
    two proud of the side below it, more than the link's recess and less than the cloud
    can show, and stops the finger on its link with the pad short of the side (a mug's
    rim, a coffee tin's lid). ``points`` are the cloud's above ``pad_top_m``."""
    lateral = np.array([-direction[1], direction[0], 0.0])
    relative = points - origin_m
    depth = relative @ direction - (contact.touch_m - origin_m @ direction)
    side = (
        (np.abs(relative @ lateral) <= kinematics.finger_half_width_m)
        & (depth <= _EDGE_DEPTH_M)
        & (points[:, 2] > pad_top_m)
    )
    if np.count_nonzero(side) < MIN_HITS:
        return False  # the side ends below the pad's top row: the pad reaches over it
    top = percentile(points[:, 2].compress(side), 98.0)
    return top < joint_m
