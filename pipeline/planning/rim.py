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
from dataclasses import dataclass

import numpy as np

from pipeline.planning.candidate import Candidate, CandidateCloud, CandidateSettings
from pipeline.planning.sdh_candidates import SdhHand, sdh_candidates

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
    :data:`_HOLLOW_SHARE` of the radius from the centre, and the camera saw
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


def rim_pinches(
    sites: list[RimSite],
    visible_m: np.ndarray,
    normal: np.ndarray,
    sdh: SdhHand,
    settings: CandidateSettings,
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

    Args:
        normal: ``(3,)`` the proposed symmetry plane's normal: the closing angle is
            measured from it, signed about +z (the score's alignment).
    """
    seen = CandidateCloud(visible_m, visible_m)
    candidates = []
    for site in sites:
        direction = site.outward
        angle = math.atan2(
            normal[0] * direction[1] - normal[1] * direction[0],
            normal[0] * direction[0] + normal[1] * direction[1],
        )
        poses = [(angle, direction, site.wall_m[2] + dz) for dz in PINCH_HEIGHTS_M]
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
