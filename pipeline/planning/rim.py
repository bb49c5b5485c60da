"""The rim of an open object (a bowl, a cup, a pitcher) and the SDH-2's pinch across its
wall there.

An open object's top is a thin wall around a hollow: the highest seen points form a ring,
and the camera, looking down over the rim, sees the inside well below it. A hand that
cannot close around such an object (wider than it opens, or its pads meeting the flaring
sides with their edges) can still pinch the wall at the rim: the thumb inside the
opening, fingers 1 and 2 outside, each closing along the line from the opening's centre
through the wall (:func:`rim_pinches`).

:func:`rim_sites` finds the ring and the sites along it from the seen cloud alone. The
camera sees the wall's inner face on the far side of the opening and its outer face on
the near side; the other face lies a wall's thickness behind, which no cloud resolves and
no mirror plane places better. The finger inside is the one whose way the cloud must
show: a wall that curves in below the rim meets its tip before its pad
(:meth:`~pipeline.planning.sdh_geometry.FingerKinematics.distal_hits`), and where the
inner face is hidden that goes unseen. So the sites are on the far side, where the
camera sees the inner face; the fingers outside meet the hidden outer face, which recedes
below the rim of a bowl or stands vertical on a cup, away from their tips. Closed
objects (a lid, a dome, a box's top) have no sites.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from pipeline.planning.candidate import Candidate, CandidateCloud, CandidateSettings
from pipeline.planning.grasp_candidates import common_reason
from pipeline.planning.pad_contact import MIN_CONTACT_ROWS
from pipeline.planning.sdh_candidates import SdhHand, sdh_candidates
from pipeline.types import GraspPlan

#: The top layer of the seen cloud taken as the rim (m): deeper than the depth noise at a
#: rim seen from a metre, shallower than any wall is tall.
RIM_BAND_M = 0.006
#: A wall this thick or thinner shows one face to the camera at a site, the other hidden
#: behind it (m): a pad closing on the hidden face stops up to this far beyond the seen
#: rim's middle.
RIM_WALL_M = 0.006
#: A hollow lies inside the ring: every top point at least this share of the ring's radius
#: from its centre ...
_HOLLOW_SHARE = 0.6
#: ... but for a few (mixed pixels at the rim's inner edge) ...
_INNER_TOP_FRACTION = 0.05
#: ... and seen points within that radius this far below the rim (m): the inside.
_HOLLOW_DEPTH_M = 0.015
#: Fewest seen points inside the ring, that far down, that show a hollow.
_MIN_INSIDE = 20
#: Fewest top points in a site's sector of the ring.
_MIN_SITE_POINTS = 5
#: The pads' centres above the rim a pinch is tried at (m): from the rim itself, the pads'
#: lower half across the wall's top, to 12 mm above it, where three taxel rows still reach
#: below the rim. Lower, the finger inside reaches deeper into the opening than the pinch
#: needs, and its tip meets a wall that curves in below the rim before its pad meets the
#: wall: a few millimetres of the cloud's error decide that, which the closing check
#: (:meth:`~pipeline.planning.sdh_geometry.FingerKinematics.distal_hits`) cannot resolve.
PINCH_HEIGHTS_M = (0.0, 0.004, 0.008, 0.012)
#: The wall under the rim is measured down to this far below the rim's top (m): the
#: ring's band and, below it, the three taxel rows a pad's contact needs
#: (:data:`~pipeline.planning.pad_contact.MIN_CONTACT_ROWS`), whose lowest lies about
#: 15 mm down when the top one meets the rim.
LEAN_DEPTH_M = 0.015
#: ... from this far below the rim's top (m): above, the rim's top itself, as wide as the
#: wall is thick, lies beyond the inner face.
_LEAN_TOP_M = RIM_BAND_M / 2.0
#: The depth bins the wall's inner face is taken in (m): a few times the points' spacing
#: at a metre, so that each holds points of the face.
_LEAN_BIN_M = 0.0015
#: Fewest bins with points that give the wall's lean (a line through them).
_MIN_LEAN_BINS = 4
#: How the refusal of a pinch whose wall leans too far begins: the planner names the
#: measurement when nothing else is feasible.
WALL_LEANS = "the wall under the rim leans"


@dataclass(frozen=True)
class RimSite:
    """A place to pinch an open object's wall at its rim (frame R, m).

    Attributes:
        wall_m: ``(3,)`` the middle of the seen rim at the site: the mean of the ring's
            points in the site's sector, at the rim's height.
        outward: ``(3,)`` horizontal unit from the opening's centre through ``wall_m``.
        centre_m: ``(3,)`` the opening's centre at the rim's height.
        radius_m: the rim's radius (the fitted circle's).
    """

    wall_m: np.ndarray
    outward: np.ndarray
    centre_m: np.ndarray
    radius_m: float

    def beyond_m(self, lateral_m: float) -> float:
        """How far beyond ``wall_m``, along the line from the centre through it, a pad
        ``lateral_m`` to the side of that line may stop on the wall (m): the rim's curve
        there (its sagitta) and a wall's thickness (:data:`RIM_WALL_M`)."""
        lateral = min(abs(lateral_m), self.radius_m)
        return self.radius_m - math.sqrt(self.radius_m**2 - lateral**2) + RIM_WALL_M

    def lean_rad(self, visible_m: np.ndarray, half_width_m: float) -> float | None:
        """How far the wall under the rim here leans from vertical (rad; positive where it
        recedes toward the opening's centre going down, as a flaring bowl's or a plate's
        does), or None where too little of it is seen.

        Measured on the wall's inner face, which the camera sees at a site (module doc):
        of the seen points within ``half_width_m`` (m) of the line from the centre through
        the site, on the site's side, from :data:`_LEAN_TOP_M` to :data:`LEAN_DEPTH_M`
        below the rim's top, those
        in each :data:`_LEAN_BIN_M` of depth at the bin's greatest distance from the
        centre (the 90th percentile: the floor and what lies inside are nearer the
        centre, mixed pixels beyond the face are few) are the face at that depth, and the
        lean is that of the straight line fitted to them (least squares). The outer face
        the fingers outside close on is hidden there; it is taken to lean as the inner
        one does (a wall of even thickness).
        """
        offsets = visible_m - self.centre_m
        along = offsets[:, :2] @ self.outward[:2]
        across = offsets[:, 0] * self.outward[1] - offsets[:, 1] * self.outward[0]
        depth = -offsets[:, 2]
        keep = (along > 0.0) & (np.abs(across) <= half_width_m)
        keep &= (depth >= _LEAN_TOP_M) & (depth <= LEAN_DEPTH_M)
        radius = np.hypot(*offsets[keep, :2].T)
        bins = np.floor(depth[keep] / _LEAN_BIN_M).astype(int)
        filled = np.unique(bins)
        if len(filled) < _MIN_LEAN_BINS:
            return None
        face = [float(np.percentile(radius[bins == k], 90.0)) for k in filled]
        slope = np.polyfit((filled + 0.5) * _LEAN_BIN_M, face, 1)[0]
        return math.atan(-slope)

    def near_half(self, points_m: np.ndarray) -> np.ndarray:
        """The ``points_m`` (``(N, 3)``, frame R) on this site's side of the opening's
        centre: what a finger inside the opening meets first, closing toward the wall; the
        far side lies behind it."""
        return points_m[(points_m[:, :2] - self.centre_m[:2]) @ self.outward[:2] > 0.0]


def ring_centre(points_xy: np.ndarray) -> tuple[np.ndarray, float]:
    """The least-squares circle through ``points_xy`` (``(N, 2)``, m): its centre and
    radius (the algebraic fit: ``x^2 + y^2 = 2 a x + 2 b y + c``, linear in ``a, b, c``).
    A rim seen over part of its turn still gives its centre, where the points' mean lies
    toward the seen part."""
    design = np.column_stack([2.0 * points_xy, np.ones(len(points_xy))])
    target = np.sum(points_xy**2, axis=1)
    (a, b, c), *_ = np.linalg.lstsq(design, target, rcond=None)
    return np.array([a, b]), math.sqrt(max(c + a * a + b * b, 0.0))


@dataclass(frozen=True)
class Rim:
    """An open object's rim as the camera saw it (frame R, m).

    Attributes:
        ring_m: ``(K, 3)`` the seen points within :data:`RIM_BAND_M` of the top.
        centre_m: ``(3,)`` the fitted circle's centre at the rim's height (:func:`ring_centre`).
        radius_m: the fitted circle's radius.
    """

    ring_m: np.ndarray
    centre_m: np.ndarray
    radius_m: float

    def circle_m(self, step_m: float) -> np.ndarray:
        """``(M, 3)`` points every ``step_m`` around the whole fitted circle, at the rim's
        height: where the rim stands on the side the camera did not see."""
        count = max(math.ceil(2.0 * math.pi * self.radius_m / step_m), 3)
        turn = np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
        return np.column_stack(
            [
                self.centre_m[0] + self.radius_m * np.cos(turn),
                self.centre_m[1] + self.radius_m * np.sin(turn),
                np.full(count, self.centre_m[2]),
            ]
        )


def find_rim(visible_m: np.ndarray) -> Rim | None:
    """The rim of an open object, or None when the object is not open.

    The rim is the seen points within :data:`RIM_BAND_M` of the cloud's top (98th
    percentile of the heights); its centre and radius are the circle fitted to them
    (:func:`ring_centre`). The object is open when those points form a ring around a
    hollow: almost all of them (:data:`_INNER_TOP_FRACTION` aside) lie at least
    :data:`_HOLLOW_SHARE` of the radius from the centre, their distances from it spread
    (standard deviation) no more than a wall is thick (:data:`RIM_WALL_M`), and the camera
    saw
    :data:`_MIN_INSIDE` points or more within that distance at least
    :data:`_HOLLOW_DEPTH_M` below the rim.

    Args:
        visible_m: ``(N, 3)`` the seen cloud, frame R.
    """
    if len(visible_m) < _MIN_INSIDE:
        return None
    top = float(np.percentile(visible_m[:, 2], 98.0))
    ring = visible_m[visible_m[:, 2] >= top - RIM_BAND_M]
    if len(ring) < 3:
        return None
    centre, radius = ring_centre(ring[:, :2])
    radii = np.hypot(*(ring[:, :2] - centre).T)
    inner = _HOLLOW_SHARE * radius
    if np.count_nonzero(radii < inner) > _INNER_TOP_FRACTION * len(ring):
        return None
    # A rim is a wall's top: its points lie about the circle within a wall's thickness.
    # The top of a rounded body (a lying tool's) fits a circle around lower points too,
    # but spreads across it by far more.
    if float(np.std(radii)) > RIM_WALL_M:
        return None
    inside = np.hypot(*(visible_m[:, :2] - centre).T) < inner
    if np.count_nonzero(inside & (visible_m[:, 2] < top - _HOLLOW_DEPTH_M)) < _MIN_INSIDE:
        return None
    return Rim(ring, np.array([centre[0], centre[1], top]), radius)


def rim_sites(rim: Rim | None, count: int, viewpoint_m: np.ndarray | None) -> list[RimSite]:
    """Up to ``count`` sites evenly around the far side of ``rim`` (none without a rim).

    Each site is the mean of the rim's points in one of ``count`` equal sectors about its
    centre (sectors with fewer than :data:`_MIN_SITE_POINTS` are skipped: the rim's unseen
    or notched parts), kept where the camera looks at the wall's inner face: the site
    lies beyond the opening's centre from the camera (module doc).

    Args:
        rim: :func:`find_rim`'s answer.
        count: sectors around the ring.
        viewpoint_m: ``(3,)`` the camera's position, frame R; unknown (None), no face
            is known to be seen and there are no sites.
    """
    if rim is None or viewpoint_m is None or count < 1:
        return []
    centre, top = rim.centre_m[:2], float(rim.centre_m[2])
    offsets = rim.ring_m[:, :2] - centre
    away = centre - np.asarray(viewpoint_m, dtype=np.float64)[:2]
    turn = np.arctan2(offsets[:, 1], offsets[:, 0]) + math.pi
    sector = np.floor(turn / (2.0 * math.pi) * count).astype(int) % count
    sites = []
    for k in range(count):
        members = sector == k
        if np.count_nonzero(members) < _MIN_SITE_POINTS:
            continue
        wall = rim.ring_m[members, :2].mean(axis=0)
        outward = wall - centre
        norm = float(np.hypot(*outward))
        if norm == 0.0 or outward @ away <= 0.0:
            continue
        sites.append(
            RimSite(
                np.array([wall[0], wall[1], top]),
                np.append(outward / norm, 0.0),
                rim.centre_m.copy(),
                rim.radius_m,
            )
        )
    return sites


def lean_limit_rad(pitch_m: float, tolerance_m: float) -> float:
    """The most a wall may lean from vertical for a vertical pad closing on it to touch
    it with :data:`~pipeline.planning.pad_contact.MIN_CONTACT_ROWS` rows, the least that
    is a side and not an edge (rad): their centres span that many pitches less one
    (``pitch_m``) in height, over which the wall may recede no more than the touch
    tolerance (``tolerance_m``). For the SDH-2 (3.4 mm) and the planner's 3 mm, 24 deg."""
    return math.atan2(tolerance_m, (MIN_CONTACT_ROWS - 1) * pitch_m)


def lean_named(plan: GraspPlan, candidates: list[Candidate]) -> GraspPlan:
    """``plan`` (from ``candidates``), its reason beginning with the wall's lean where it
    is refused and the lean ruled out a pinch at the rim (:func:`rim_pinches`): the
    measurement that rules the hand out on an open object, which the most common reason
    among the enveloping grasps (their pads meeting a rim's edge) does not name."""
    leaning = [c.summary.reason for c in candidates if c.summary.reason.startswith(WALL_LEANS)]
    if plan.status != "refused" or not leaning:
        return plan
    reason, count = common_reason(leaning)
    return replace(plan, reason=f"{reason} ({count} pinches at the rim); {plan.reason}")


def rim_pinches(
    sites: list[RimSite],
    visible_m: np.ndarray,
    normal: np.ndarray,
    sdh: SdhHand,
    settings: CandidateSettings,
    surface_m: np.ndarray | None = None,
) -> list[Candidate]:
    """SDH-2 pinches across the wall at each of ``sites``: fingers 1 and 2 facing the
    thumb (spread 0), the palm's x axis along the site's outward direction (the thumb
    inside the opening, closing outward), the pads' centres at each of
    :data:`PINCH_HEIGHTS_M` from the rim, planned on the seen cloud ``visible_m`` alone
    (the mirror image adds nothing a pinch at a seen rim needs).

    The closing line goes through the wall at the rim; the pads meet the surface on the
    site's half of the object (:meth:`RimSite.near_half`), the fingers outside up to
    :meth:`RimSite.beyond_m` beyond the rim's middle (the hidden outer face, where the rim
    curves away from the closing line at their bases' offset). Every other check
    is :func:`~pipeline.planning.sdh_candidates.sdh_candidates`': the whole finger's
    closing among them, so a pad height at which the thumb's tip meets a wall curving in
    below the rim before its pad meets the wall is rejected.

    No pinch is tried at a site where the wall leans more than a pad's rows can follow
    (:meth:`RimSite.lean_rad`, :func:`lean_limit_rad`).

    Args:
        normal: ``(3,)`` the proposed symmetry plane's normal: the closing angle is
            measured from it, signed about +z (the score's alignment).
        surface_m: ``(M, 3)`` the seen surface the wall's lean is measured on, where
            ``visible_m`` has volume added under it (default ``visible_m``).
    """
    surface_m = visible_m if surface_m is None else surface_m
    seen = CandidateCloud(visible_m, visible_m)
    limit = lean_limit_rad(sdh.pad.pitch_m, settings.touch_tolerance_m)
    candidates = []
    for site in sites:
        direction = site.outward
        angle = math.atan2(
            normal[0] * direction[1] - normal[1] * direction[0],
            normal[0] * direction[0] + normal[1] * direction[1],
        )
        poses = [(angle, direction, site.wall_m[2] + dz) for dz in PINCH_HEIGHTS_M]
        lean = site.lean_rad(surface_m, _pads_half_width_m(sdh))
        if lean is not None and lean > limit:
            reason = leaning_reason(lean, limit)
            candidates += [Candidate.rejected(angle, height, 0.0, reason) for _, _, height in poses]
            continue
        near = site.near_half(visible_m)
        candidates += sdh_candidates(
            seen,
            site.wall_m,
            poses,
            0.0,
            sdh,
            settings,
            CandidateCloud(near, near),
            site.beyond_m(sdh.turning_lateral_m()),
        )
    return candidates


def _pads_half_width_m(sdh: SdhHand) -> float:
    """How far to either side of a pinch's closing line its pads reach (m): fingers 1
    and 2's offset and half a pad."""
    return sdh.turning_lateral_m() + sdh.pad.cols * sdh.pad.pitch_m / 2.0


def leaning_reason(lean_rad: float, limit_rad: float) -> str:
    """Why no pad holds a wall leaning ``lean_rad`` from vertical, more than ``limit_rad``
    (:func:`lean_limit_rad`)."""
    return (
        f"{WALL_LEANS} {math.degrees(lean_rad):.0f} deg from vertical (more than "
        f"{math.degrees(limit_rad):.0f}): the pads would meet only its edge"
    )


def wall_lean_rad(sites: list[RimSite], visible_m: np.ndarray, sdh: SdhHand) -> float | None:
    """The lean of the wall under the rim (rad, :meth:`RimSite.lean_rad`): the median
    over ``sites`` where it is measured (a spout or a handle is one site of several), or
    None where it is measured at none."""
    leans = [site.lean_rad(visible_m, _pads_half_width_m(sdh)) for site in sites]
    measured = [lean for lean in leans if lean is not None]
    return float(np.median(measured)) if measured else None


def off_leaning_wall(
    candidates: list[Candidate], rim: Rim, lean_rad: float, limit_rad: float
) -> list[Candidate]:
    """``candidates`` with every feasible one whose pads are predicted to touch the wall
    under ``rim`` within :data:`LEAN_DEPTH_M` of its top rejected, the wall leaning
    ``lean_rad`` from vertical, more than ``limit_rad`` (:func:`lean_limit_rad`): a
    vertical pad meets such a wall with a row or two, at the rim's outer edge from
    outside, at the lowest rows' reach from inside, whatever the cloud's few millimetres
    of noise and mixed pixels at the rim predict. Where the wall is at least that far
    from the rim's middle: a wall's thickness (:data:`RIM_WALL_M`) inside the rim's
    fitted circle, less what the lean takes it in at the contact's depth. A pad meeting
    the wall lower down, where it stands steeper, is kept. ``candidates`` are returned
    as they are where ``lean_rad`` is within the limit."""
    if lean_rad <= limit_rad:
        return candidates
    reason = leaning_reason(lean_rad, limit_rad)
    kept = []
    for candidate in candidates:
        contacts = candidate.predicted_contacts
        depth = rim.centre_m[2] - contacts[:, 2]
        radius = np.hypot(*(contacts[:, :2] - rim.centre_m[:2]).T)
        inner = rim.radius_m - RIM_WALL_M - np.clip(depth, 0.0, None) * math.tan(lean_rad)
        on_wall = (depth <= LEAN_DEPTH_M) & (radius >= inner)
        if candidate.summary.feasible and np.any(on_wall):
            summary = candidate.summary
            candidate = Candidate.rejected(
                math.radians(summary.closing_angle_deg),
                summary.height_m,
                math.radians(summary.spread_deg),
                reason,
            )
        kept.append(candidate)
    return kept
