"""Ranked top-grasp candidates: closing directions and heights enumerated on the completed
cloud, infeasible ones rejected, the rest scored.

A candidate closes along a horizontal direction at an angle from the proposed symmetry
plane's normal, with its pads' centres at a height, on the cloud completed by mirroring
it through the proposed plane (moved back if needed to cover every visible point,
:func:`covering_plane`). It is *feasible* when the hand can descend around the object
without touching it (its opened fingers and palm clear every cloud point above the
fingertips), close without touching it other than with its pads, and every pad meets a
side (not only an edge or the top) with the fingertips above the table. Its score, in
[0, 1], multiplies three factors:

* *contact*: the smallest predicted pad contact quality over the fingers
  (:attr:`PadContact.quality`, from :func:`pad_coverage`): each finger must meet the
  surface squarely with its pad, so the grasp has contacts on opposing sides - a pad over
  a rim, a cap or an edge covers little, a pad grazing a curved side meets it inclined;
* *alignment* ``(1 + |cos angle|) / 2``: closing along the plane normal puts contacts on
  the visible front and the hidden back, which is what the estimator learns most from;
* *stability* ``1 / (1 + w h / f)``: the contact height ``h`` above the table over the
  object's half-footprint ``f`` along the closing direction is the lever of any residual
  push of the fingers; lower grasps on a wider footprint tip less (``w``: the planner's
  ``tipping_weight``).

Parallel-jaw candidates are built by :func:`parallel_candidate`, SDH-2 candidates by
:func:`sdh_candidate`; both return a :class:`Candidate`.
"""

from __future__ import annotations

import functools
import math
from abc import abstractmethod
from collections import Counter
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..pad_layout import pad_grid
from ..params import param
from ..stages import GraspPlanner
from ..types import (
    GraspCandidate,
    GraspPlan,
    GripperSpec,
    PadLayout,
    PointCloud,
    SymmetryInit,
    SymmetryPlane,
)
from . import sdh_geometry as sdh
from .grasp_geometry import front_to_back, hand_pose


@dataclass(frozen=True)
class PadContact:
    """Where a pad moving toward the surface stops and how much of it touches.

    Attributes:
        touch_m: position of the pad's flat surface along its motion when it stops (m).
        coverage: fraction of its taxels within the tolerance of the surface then.
        points: ``(K, 3)`` surface points under those taxels.
        inclination_rad: angle between the surface's normal there and the pad's.
    """

    touch_m: float
    coverage: float
    points: np.ndarray
    inclination_rad: float = 0.0

    @property
    def quality(self) -> float:
        """Coverage times ``cos^2`` of the inclination: an inclined surface takes the pad's
        force partly along itself, and the pad slides off it."""
        return self.coverage * math.cos(self.inclination_rad) ** 2


#: Fewest cloud points inside a part of the hand that make a collision: fewer are taken
#: for depth noise and mixed pixels at the object's silhouette (about 2 mm apart, a real
#: overlap of 5 x 5 mm holds more).
_MIN_HITS = 8
#: Fewest taxel rows a pad must touch for its contact to be a side of the object.
_MIN_CONTACT_ROWS = 3


@dataclass(frozen=True)
class PadTaxels:
    """A vertical pad's taxel grid as it moves horizontally (metres): ``col_u`` the
    columns' offsets across the motion (evenly ``pitch_m`` apart), ``row_z`` the rows'
    heights, ``row_recess`` how far each row lies behind the pad's flat surface (a tip
    curving away from the object)."""

    col_u: np.ndarray
    row_z: np.ndarray
    row_recess: np.ndarray
    pitch_m: float


def flat_pad_taxels(pad: PadLayout, centre_z_m: float) -> PadTaxels:
    """A flat vertical pad, rows along z around ``centre_z_m``."""
    positions, _ = pad_grid(pad.rows, pad.cols, pad.pitch_m)
    grid = positions.reshape(pad.rows, pad.cols, 3)
    return PadTaxels(grid[0, :, 1], centre_z_m - grid[:, 0, 0], np.zeros(pad.rows), pad.pitch_m)


def sdh_flat_part_edge_m(pad: PadLayout) -> float:
    """How far below the SDH-2 distal pad's centre its flat rows end (negative: above
    it): the curved tip rows below them lie back from a side the pad presses on."""
    flat_rows = pad.rows - sdh.DISTAL_PAD_CURVED_ROWS
    return (flat_rows - (pad.rows - 1) / 2.0 - 0.5) * pad.pitch_m


def sdh_distal_taxels(pad: PadLayout, centre_z_m: float) -> PadTaxels:
    """An SDH-2 distal pad on a vertical distal link: rows along the link toward the tip
    (down), the curved tip rows recessed behind the flat surface."""
    positions, _ = pad_grid(
        pad.rows, pad.cols, pad.pitch_m, sdh.DISTAL_PAD_CURVED_ROWS, sdh.DISTAL_PAD_CURVE_RADIUS_M
    )
    grid = positions.reshape(pad.rows, pad.cols, 3)
    return PadTaxels(grid[0, :, 1], centre_z_m - grid[:, 0, 0], -grid[:, 0, 2], pad.pitch_m)


def pad_coverage(
    points_robot: np.ndarray,
    origin_m: np.ndarray,
    direction: np.ndarray,
    taxels: PadTaxels,
    tolerance_m: float,
) -> PadContact | None:
    """Predict a pad's contact with the surface sampled by ``points_robot``.

    The pad moves along ``direction`` (horizontal unit); its columns are offset across the
    motion from the line through ``origin_m``. Each taxel sees the points within half a
    pitch of it across and in height; their median position along ``direction`` is the
    surface in front of it. The pad stops when its first taxel reaches the surface; the
    taxels whose surface is then within ``tolerance_m`` count as touching.

    Returns:
        The contact, or None when no point lies in front of any taxel or the touching
        taxels span fewer than three rows (about 10 mm: the pad meets an edge or a
        horizontal top, not a side).
    """
    direction = np.asarray(direction, dtype=np.float64)
    lateral = np.array([-direction[1], direction[0], 0.0])
    half = taxels.pitch_m / 2.0
    z = points_robot[:, 2]
    relative = points_robot - origin_m
    u = relative @ lateral
    near = (
        (u >= taxels.col_u.min() - half)
        & (u <= taxels.col_u.max() + half)
        & (z >= taxels.row_z.min() - half)
        & (z <= taxels.row_z.max() + half)
    )
    u, z, relative, kept = u[near], z[near], relative[near], points_robot[near]
    cols = len(taxels.col_u)
    col = np.clip(np.round((u - taxels.col_u[0]) / taxels.pitch_m).astype(int), 0, cols - 1)
    order = np.argsort(taxels.row_z)
    sorted_z = taxels.row_z[order]
    row = order[np.searchsorted((sorted_z[1:] + sorted_z[:-1]) / 2.0, z)]
    inside = np.abs(z - taxels.row_z[row]) <= half
    if not np.any(inside):
        return None
    taxel = (row * cols + col)[inside]
    depth, kept = (relative @ direction)[inside], kept[inside]
    by_taxel = np.lexsort((depth, taxel))
    taxel, depth, kept = taxel[by_taxel], depth[by_taxel], kept[by_taxel]
    seen, first, counts = np.unique(taxel, return_index=True, return_counts=True)
    surface = depth[first + counts // 2] + taxels.row_recess[seen // cols]
    # The first touch: the nearest surface seen by at least two points (a single point may
    # be a mixed pixel at the silhouette).
    supported = counts >= 2
    touch = float(surface[supported].min() if np.any(supported) else surface.min())
    touching = seen[surface <= touch + tolerance_m]
    if len(np.unique(touching // cols)) < _MIN_CONTACT_ROWS:
        return None  # an edge or a horizontal top, not a side
    return PadContact(
        touch_m=touch + float(origin_m @ direction),
        coverage=len(touching) / (len(taxels.row_z) * cols),
        points=kept[np.isin(taxel, touching)],
        inclination_rad=_inclination(
            taxels.col_u[seen % cols], taxels.row_z[seen // cols], surface, touch, tolerance_m
        ),
    )


def _inclination(
    u: np.ndarray, z: np.ndarray, surface: np.ndarray, touch: float, tolerance_m: float
) -> float:
    """Angle between the pad's normal and the surface's, from a plane
    ``surface = a + b u + c z`` fitted over the taxels whose surface lies within three
    tolerances of the touch (too few of them, or a degenerate layout: 0)."""
    near = surface <= touch + 3.0 * tolerance_m
    design = np.column_stack([np.ones(np.count_nonzero(near)), u[near], z[near]])
    if len(design) < 4 or np.linalg.matrix_rank(design) < 3:
        return 0.0
    _, b, c = np.linalg.lstsq(design, surface[near], rcond=None)[0]
    return float(np.arctan(np.hypot(b, c)))


def covering_plane(points_robot: np.ndarray, plane: SymmetryPlane) -> SymmetryPlane:
    """``plane`` moved back along its normal, if needed, so that the cloud mirrored through
    it reaches the farthest visible point: at least midway between the nearest and the
    farthest visible points along the normal (1st and 99th percentiles), seen from the
    visible side. A plane through the cloud's centroid (PCA) lies too close to the camera
    when the view also sees the object's top reaching far back; the completed object then
    ends before a top it must hold up."""
    normal = plane.normal
    along = points_robot @ normal
    middle = float(np.mean(np.percentile(along, [1.0, 99.0])))
    backward = front_to_back(points_robot, normal) @ normal > 0.0
    offset = max(plane.offset_m, middle) if backward else min(plane.offset_m, middle)
    return SymmetryPlane(plane.theta_rad, offset)


def candidate_score(
    coverages: tuple[float, ...], angle_rad: float, tipping_ratio: float, tipping_weight: float
) -> float:
    """The module docstring's score: contact x alignment x stability, in [0, 1]."""
    alignment = (1.0 + abs(math.cos(angle_rad))) / 2.0
    return min(coverages) * alignment / (1.0 + tipping_weight * tipping_ratio)


def footprint_half_m(completed_robot: np.ndarray, direction: np.ndarray) -> float:
    """Half the object's extent along ``direction`` (2nd to 98th percentile), m."""
    low, high = np.percentile(completed_robot @ direction, [2.0, 98.0])
    return max(float(high - low) / 2.0, 1e-3)


def height_grid(low_m: float, high_m: float, step_m: float) -> np.ndarray:
    """Pad-centre heights from ``high_m`` down to ``low_m`` (inclusive), ``step_m`` apart;
    only ``low_m`` when the range is empty."""
    if high_m <= low_m:
        return np.array([low_m])
    heights = high_m - step_m * np.arange(math.floor((high_m - low_m) / step_m + 1e-9) + 1)
    return heights if heights[-1] <= low_m + 1e-9 else np.append(heights, low_m)


@dataclass(frozen=True)
class Candidate:
    """One evaluated grasp: its summary (:class:`GraspCandidate`) and, when feasible, the
    plan's geometry.

    Attributes:
        summary: what the ranking records.
        T_robot_hand: palm pose.
        opening_m: opening to pre-shape to before the descent.
        spread_rad: SDH base rotation (0 for a parallel gripper).
        predicted_contacts: ``(K, 3)`` surface points the pads are expected to touch.
    """

    summary: GraspCandidate
    T_robot_hand: np.ndarray = field(default_factory=lambda: np.eye(4))
    opening_m: float = 0.0
    spread_rad: float = 0.0
    predicted_contacts: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


def _rejected(angle_rad: float, height_m: float, spread_rad: float, reason: str) -> Candidate:
    return Candidate(
        GraspCandidate(
            closing_angle_deg=math.degrees(angle_rad),
            height_m=height_m,
            spread_deg=math.degrees(spread_rad),
            width_m=math.nan,
            contact_coverage=(),
            tipping_ratio=math.nan,
            score=0.0,
            feasible=False,
            reason=reason,
        )
    )


@dataclass(frozen=True)
class CandidateSettings:
    """What every candidate builder needs besides the geometry (metres)."""

    table_height_m: float
    table_clearance_m: float
    descent_clearance_m: float
    touch_tolerance_m: float
    tipping_weight: float


@dataclass(frozen=True)
class CandidateParams:
    """The parameters both shipped planners share for ranking candidates (each planner's
    ``Params`` extends these)."""

    strategy: Literal["candidates", "paper"] = param(
        "candidates",
        "candidates: rank closing directions, heights (and pre-shapes) on the cloud; "
        "paper: the paper's single grasp at the top (its reproductions)",
    )
    angle_step_deg: float = param(
        15.0, "candidates: closing directions tried this far apart (deg)", above=0.0
    )
    height_step_m: float = param(
        0.01, "candidates: pad heights tried this far apart (m)", above=0.0
    )
    descent_clearance_m: float = param(
        0.004, "candidates: least gap between the descending hand and the cloud (m)"
    )
    touch_tolerance_m: float = param(
        0.003, "candidates: surface within this of a pad at its first touch counts (m)"
    )
    tipping_weight: float = param(
        0.2, "candidates: weight of the contact height / half-footprint in the score"
    )
    top_margin_m: float = param(0.005, "pad top edge below the object's top (m)")
    table_clearance_m: float = param(0.01, "lowest fingertip height above the table (m)")
    cloud_base_above_table_m: float = param(
        0.02, "the table lies this far below the cloud's lowest point (m)"
    )


@dataclass(frozen=True)
class CandidateFrame:
    """What a planner enumerates candidates on: the cloud completed by
    :func:`covering_plane`, the pad heights to try and the settings."""

    completed: np.ndarray
    heights_m: np.ndarray
    settings: CandidateSettings


def candidate_frame(
    points_robot: np.ndarray,
    plane: SymmetryPlane,
    pad: PadLayout,
    params: CandidateParams,
    *,
    pad_centre_to_fingertip_m: float,
    keep_above_cloud: bool,
    contact_edge_below_centre_m: float,
) -> CandidateFrame:
    """The completed cloud, and pad-centre heights every ``params.height_step_m`` from the
    lowest allowed - fingertips ``table_clearance_m`` above the table (taken
    ``cloud_base_above_table_m`` below the cloud), and with ``keep_above_cloud`` the lower
    edge of the pad's touching part (``contact_edge_below_centre_m`` below its centre;
    negative above it) above the cloud's bottom - to ``top_margin_m`` below the cloud's top (the
    pads may reach above a short object; their predicted contact says how much of them
    touches)."""
    completed = np.concatenate(
        [points_robot, covering_plane(points_robot, plane).mirror(points_robot)]
    )
    table = float(points_robot[:, 2].min()) - params.cloud_base_above_table_m
    z_bottom, z_top = np.percentile(completed[:, 2], [2.0, 98.0])
    lowest = table + params.table_clearance_m + pad_centre_to_fingertip_m
    if keep_above_cloud:
        lowest = max(lowest, float(z_bottom) + contact_edge_below_centre_m)
    return CandidateFrame(
        completed,
        height_grid(lowest, float(z_top) - params.top_margin_m, params.height_step_m),
        CandidateSettings(
            table_height_m=table,
            table_clearance_m=params.table_clearance_m,
            descent_clearance_m=params.descent_clearance_m,
            touch_tolerance_m=params.touch_tolerance_m,
            tipping_weight=params.tipping_weight,
        ),
    )


@dataclass(frozen=True)
class ParallelHand:
    """A parallel-jaw gripper's geometry (m) for :func:`parallel_candidate`."""

    pad: PadLayout
    aperture_m: float
    palm_to_pad_centre_m: float
    pad_centre_to_fingertip_m: float
    jaw_half_width_m: float
    housing_half_length_m: float
    housing_half_width_m: float
    housing_depth_m: float


def parallel_candidate(
    visible: np.ndarray,
    completed: np.ndarray,
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
    """A parallel-jaw grasp closing along ``direction`` (front to back) through ``centre_m``
    with the pad centres at ``height_m``.

    Both jaws descend clear of every point above the fingertips between their paths: the
    front jaw ``jaw_clearance_m`` before the visible surface there, or less (down to
    ``settings.descent_clearance_m``) when the object leaves less room in the aperture; the
    back jaw at least that plus ``back_margin_m`` behind the completed back, whose position
    is only the mirror plane's guess. The housing must pass above the object's top.
    """
    s = settings
    lateral = np.array([-direction[1], direction[0], 0.0])
    fingertip_z = height_m - hand.pad_centre_to_fingertip_m
    if fingertip_z < s.table_height_m + s.table_clearance_m:
        return _rejected(angle_rad, height_m, 0.0, "fingertips below the table clearance")

    def column(points: np.ndarray) -> np.ndarray:
        across = np.abs((points - centre_m) @ lateral)
        return points[(across <= hand.jaw_half_width_m) & (points[:, 2] >= fingertip_z)]

    front_points, all_points = column(visible), column(completed)
    if len(front_points) == 0:
        return _rejected(angle_rad, height_m, 0.0, "no visible surface between the jaws")
    front = float(np.percentile(front_points @ direction, 2.0))
    back = float(np.percentile(all_points @ direction, 98.0))
    width = back - front
    room = hand.aperture_m - width - back_margin_m
    if room < 2.0 * s.descent_clearance_m:
        return _rejected(
            angle_rad,
            height_m,
            0.0,
            f"{width * 1e3:.0f} mm wide between the jaws' paths, aperture "
            f"{hand.aperture_m * 1e3:.0f} mm",
        )
    front_pad = front - min(jaw_clearance_m, room / 2.0)
    middle = front_pad + hand.aperture_m / 2.0
    position = centre_m + (middle - centre_m @ direction) * direction
    position[2] = height_m + hand.palm_to_pad_centre_m
    housing_bottom = position[2] - hand.housing_depth_m
    offset = completed - position
    under_housing = (
        (np.abs(offset @ direction) <= hand.housing_half_length_m + s.descent_clearance_m)
        & (np.abs(offset @ lateral) <= hand.housing_half_width_m + s.descent_clearance_m)
        & (completed[:, 2] >= housing_bottom - s.descent_clearance_m)
    )
    if np.count_nonzero(under_housing) >= _MIN_HITS:
        return _rejected(angle_rad, height_m, 0.0, "the housing would hit the object's top")

    contacts = []
    taxels = flat_pad_taxels(hand.pad, height_m)
    for points, sign in ((visible, 1.0), (completed, -1.0)):
        contact = pad_coverage(points, position, sign * direction, taxels, s.touch_tolerance_m)
        if contact is None:
            side = "front" if sign > 0 else "back"
            return _rejected(angle_rad, height_m, 0.0, f"no surface before the {side} pad")
        contacts.append(contact)
    coverages = tuple(c.quality for c in contacts)
    tipping = (height_m - s.table_height_m) / footprint_half_m(completed, direction)
    return Candidate(
        GraspCandidate(
            closing_angle_deg=math.degrees(angle_rad),
            height_m=height_m,
            spread_deg=0.0,
            width_m=width,
            contact_coverage=coverages,
            tipping_ratio=tipping,
            score=candidate_score(coverages, angle_rad, tipping, s.tipping_weight),
            feasible=True,
        ),
        T_robot_hand=hand_pose(position, direction),
        opening_m=hand.aperture_m,
        predicted_contacts=contacts[0].points,
    )


#: SDH-2 pre-shapes: base rotation -> where the object's centre sits on the palm's x axis
#: (m): at 60 deg the fingers face the palm axis; at 0 fingers 1 and 2 face the thumb and
#: the object sits midway between the thumb's base and theirs.
SDH_SPREADS = {
    math.radians(60.0): 0.0,
    0.0: (sdh.FINGER_BASES_M[0, 0] + sdh.FINGER_BASES_M[2, 0]) / 2.0,
}
#: Steps of the pre-shape search: proximal angles tried below the contact angle (rad).
_OPEN_STEP_RAD = math.radians(3.0)


def sdh_candidate(
    visible: np.ndarray,
    completed: np.ndarray,
    centre_m: np.ndarray,
    direction: np.ndarray,
    angle_rad: float,
    height_m: float,
    spread_rad: float,
    pad: PadLayout,
    aperture_m: float,
    settings: CandidateSettings,
) -> Candidate:
    """An SDH-2 grasp at base rotation ``spread_rad`` (a key of :data:`SDH_SPREADS`), the
    palm's x axis along ``direction`` (thumb on the front side), distal pad centres at
    ``height_m``. Fingers 1 and 2 facing the thumb (spread 0) need the object as wide as
    their two pads across the closing line.

    Each finger's contact angle is the proximal angle at which its distal pad (distal link
    parallel to the palm axis) touches the ``completed`` cloud (``visible`` and mirrored)
    (:func:`pad_coverage`); the palm
    height puts the pads' centres at ``height_m`` at those angles. The pre-shape is the
    most closed common proximal angle, at least 3 deg before the earliest contact, at which
    every finger, the knuckles and the palm descend clear of the cloud
    (:func:`sdh_geometry.finger_profile`); ``opening_m`` is that pre-shape's opening. From
    there to its contact no finger's knuckle or proximal link may meet the cloud
    (:func:`sdh_geometry.closing_hits`).
    """
    s = settings
    x_hand = np.array([direction[0], direction[1], 0.0])
    y_hand = np.array([direction[1], -direction[0], 0.0])
    palm_xy = centre_m - SDH_SPREADS[spread_rad] * x_hand
    rotation = np.column_stack([x_hand[:2], y_hand[:2]])
    facings = sdh.finger_facings(spread_rad) @ rotation.T
    taxels = sdh_distal_taxels(pad, height_m)
    if spread_rad == 0.0:
        # Fingers 1 and 2 facing the thumb meet the back 33 mm either side of the closing
        # line: the object must be wide enough there for both their pads.
        in_band = np.abs(completed[:, 2] - height_m) <= pad.rows * pad.pitch_m / 2.0
        across = completed[in_band] @ y_hand
        span = sdh.FINGER_BASES_M[0, 1] + pad.cols * pad.pitch_m / 2.0
        if len(across) == 0 or np.ptp(np.percentile(across, [2.0, 98.0])) < 2.0 * span:
            return _rejected(
                angle_rad, height_m, spread_rad, "too narrow for fingers facing the thumb"
            )
    # Fingers meet an object off the palm axis inclined, so the palm is moved once, onto
    # the centre of the contacts predicted from the first guess.
    for attempt in range(2):
        bases = palm_xy[:2] + sdh.FINGER_BASES_M @ rotation.T
        found = _finger_contacts(completed, bases, facings, taxels, s.touch_tolerance_m)
        if isinstance(found, str):
            return _rejected(angle_rad, height_m, spread_rad, found)
        contacts, alphas = found
        if attempt == 0:
            palm_xy = _contact_centre(contacts, x_hand, y_hand, spread_rad) - (
                SDH_SPREADS[spread_rad] * x_hand
            )
    palm_z = height_m + float(np.mean(sdh.distal_pad_depth_m(np.array(alphas))))
    depth_below_palm = palm_z - completed[:, 2]
    radial = np.hypot(*(completed[:, :2] - palm_xy[:2]).T)
    palm_hit = (radial <= sdh.PALM_RADIUS_M + s.descent_clearance_m) & (
        depth_below_palm <= sdh.BASE_DEPTH_M + s.descent_clearance_m
    )
    if np.count_nonzero(palm_hit) >= _MIN_HITS:
        return _rejected(angle_rad, height_m, spread_rad, "the palm would hit the object's top")
    open_alpha = _clear_preshape(completed, bases, facings, depth_below_palm, min(alphas), s)
    if open_alpha is None:
        return _rejected(
            angle_rad, height_m, spread_rad, "the fingers cannot open around the object"
        )
    opening = sdh.opening_for_alpha(open_alpha)
    if opening > aperture_m + 1e-9:
        return _rejected(angle_rad, height_m, spread_rad, "wider than the hand opens")
    if _closing_collides(visible, bases, facings, palm_z, open_alpha, alphas, s):
        return _rejected(
            angle_rad, height_m, spread_rad, "a proximal link would hit the object while closing"
        )
    # Closing from the pre-shape, the fingertips are lowest where the proximal links pass
    # closest to vertical.
    steepest = 0.0 if open_alpha <= 0.0 <= max(alphas) else min(abs(open_alpha), abs(max(alphas)))
    lowest_tip = palm_z - (
        sdh.KNUCKLE_DEPTH_M + sdh.PROXIMAL_LENGTH_M * math.cos(steepest) + sdh.DISTAL_LENGTH_M
    )
    if lowest_tip < s.table_height_m + s.table_clearance_m:
        return _rejected(angle_rad, height_m, spread_rad, "fingertips below the table clearance")
    coverages = tuple(c.quality for c in contacts)
    tipping = (height_m - s.table_height_m) / footprint_half_m(completed, x_hand)
    in_band = np.abs(completed[:, 2] - height_m) <= pad.rows * pad.pitch_m / 2.0
    width = float(np.ptp(completed[in_band] @ x_hand)) if np.any(in_band) else math.nan
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
            score=candidate_score(coverages, angle_rad, tipping, s.tipping_weight),
            feasible=True,
        ),
        T_robot_hand=hand_pose(position, x_hand),
        opening_m=opening,
        spread_rad=spread_rad,
        predicted_contacts=np.concatenate([contacts[i].points for i in order]),
    )


def _finger_contacts(
    completed: np.ndarray,
    bases: np.ndarray,
    facings: np.ndarray,
    taxels: PadTaxels,
    tolerance_m: float,
) -> tuple[list[PadContact], list[float]] | str:
    """Each finger's predicted distal pad contact and its proximal angle there, or why a
    finger finds none."""
    contacts, alphas = [], []
    for finger, base, facing in zip(sdh.FINGERS, bases, facings, strict=True):
        origin = np.array([base[0], base[1], 0.0])
        direction = np.array([facing[0], facing[1], 0.0])
        contact = pad_coverage(completed, origin, direction, taxels, tolerance_m)
        if contact is None:
            return f"{finger} meets no surface"
        alpha = float(sdh.alpha_for_reach(contact.touch_m - origin @ direction))
        if not abs(alpha) < sdh.JOINT_LIMIT_RAD:
            return f"{finger} cannot reach the surface"
        contacts.append(contact)
        alphas.append(alpha)
    return contacts, alphas


def _contact_centre(
    contacts: list[PadContact], x_hand: np.ndarray, y_hand: np.ndarray, spread_rad: float
) -> np.ndarray:
    """Where the object's centre lies among the fingers' predicted contacts (f1, f2,
    thumb), robot xy with z 0: midway between the thumb's contact and the fingers' along
    the palm's x axis, between finger 1's and finger 2's across it (spread 0), or the
    circumcentre of the three contacts (fingers facing the palm axis)."""
    points = np.array([c.points.mean(axis=0)[:2] for c in contacts])
    if spread_rad == 0.0:
        x = (points[:2].mean(axis=0) @ x_hand[:2] + points[2] @ x_hand[:2]) / 2.0
        y = points[:2].mean(axis=0) @ y_hand[:2]
        return np.append(x * x_hand[:2] + y * y_hand[:2], 0.0)
    a, b, c = points
    d = 2.0 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
    if abs(d) < 1e-9:
        return np.append(points.mean(axis=0), 0.0)
    norms = (a @ a, b @ b, c @ c)
    ux = (norms[0] * (b[1] - c[1]) + norms[1] * (c[1] - a[1]) + norms[2] * (a[1] - b[1])) / d
    uy = (norms[0] * (c[0] - b[0]) + norms[1] * (a[0] - c[0]) + norms[2] * (b[0] - a[0])) / d
    return np.array([ux, uy, 0.0])


def _clear_preshape(
    completed: np.ndarray,
    bases: np.ndarray,
    facings: np.ndarray,
    depth_below_palm: np.ndarray,
    contact_alpha: float,
    s: CandidateSettings,
) -> float | None:
    """The most closed proximal angle on a 3-deg grid, at least 3 deg before
    ``contact_alpha``, at which every finger descends clear of the cloud; None when none
    does."""
    corridors = []
    for base, facing in zip(bases, facings, strict=True):
        relative = completed[:, :2] - base
        across = np.abs(relative @ np.array([-facing[1], facing[0]]))
        near = across <= sdh.FINGER_HALF_WIDTH_M + s.descent_clearance_m
        corridors.append((relative[near] @ facing, depth_below_palm[near]))
    step = math.floor((contact_alpha - _OPEN_STEP_RAD) / _OPEN_STEP_RAD)
    while step * _OPEN_STEP_RAD > -sdh.JOINT_LIMIT_RAD:
        grid, reach = _swept_profile(step, s.descent_clearance_m)
        clear = True
        for t, d in corridors:
            index = np.round((t - grid[0]) / _PROFILE_STEP_M).astype(int)
            inside = (index >= 0) & (index < len(grid))
            if np.count_nonzero(d[inside] <= reach[index[inside]]) >= _MIN_HITS:
                clear = False
                break
        if clear:
            return step * _OPEN_STEP_RAD
        step -= 1
    return None


def _closing_collides(
    visible: np.ndarray,
    bases: np.ndarray,
    facings: np.ndarray,
    palm_z: float,
    open_alpha: float,
    contact_alphas: list[float],
    s: CandidateSettings,
) -> bool:
    """Whether a finger's knuckle or proximal link meets the visible cloud on its way from
    the pre-shape to its contact angle (checked every 3 deg and at the contact): on a tall
    object a low grasp swings the proximal links into its upper part. Only seen points
    count: the mirrored ones are where the plane guesses the back, too uncertain to veto a
    grasp on."""
    depth_below_palm = palm_z - visible[:, 2]
    for base, facing, contact in zip(bases, facings, contact_alphas, strict=True):
        relative = visible[:, :2] - base
        across = np.abs(relative @ np.array([-facing[1], facing[0]]))
        near = across <= sdh.FINGER_HALF_WIDTH_M + s.touch_tolerance_m
        t, d = relative[near] @ facing, depth_below_palm[near]
        for alpha in [*np.arange(open_alpha, contact, _OPEN_STEP_RAD), contact]:
            if np.count_nonzero(sdh.closing_hits(t, d, alpha, s.touch_tolerance_m)) >= _MIN_HITS:
                return True
    return False


#: Resolution of the finger profiles the pre-shape search compares the cloud with (m).
_PROFILE_STEP_M = 0.001


@functools.lru_cache(maxsize=256)
def _swept_profile(step: int, clearance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The finger profile at proximal angle ``step`` x 3 deg, grown by ``clearance_m`` in
    both directions."""
    from scipy.ndimage import maximum_filter1d  # deferred: planners load with `plugins`

    grid, depth = sdh.finger_profile(step * _OPEN_STEP_RAD, _PROFILE_STEP_M)
    width = 2 * math.ceil(clearance_m / _PROFILE_STEP_M) + 1
    return grid, maximum_filter1d(depth, width) + clearance_m


def closing_angles(step_deg: float) -> np.ndarray:
    """Closing angles from the plane normal (rad): 0, then outward either side in
    ``step_deg`` steps, up to 90 deg (a closing line and its reverse are one grasp)."""
    side = np.arange(step_deg, 90.0 + 1e-9, step_deg)
    angles = [0.0, *(a for pair in zip(side, -side, strict=True) for a in pair)]
    if side.size and abs(side[-1] - 90.0) < 1e-9:
        angles.pop()  # -90 deg is the same line as +90 deg
    return np.radians(angles)


def plan_from_candidates(
    gripper: str, candidates: list[Candidate], pregrasp_height_m: float, aperture_m: float
) -> GraspPlan:
    """The best feasible candidate as a plan, with every candidate ranked; refused (with
    the most common reason) when none is feasible."""
    ranked = sorted(candidates, key=lambda c: (not c.summary.feasible, -c.summary.score))
    summaries = tuple(c.summary for c in ranked)
    best = ranked[0]
    if not best.summary.feasible:
        reasons = Counter(c.summary.reason for c in ranked)
        reason, count = reasons.most_common(1)[0]
        return GraspPlan(
            gripper=gripper,
            status="refused",
            T_robot_hand=best.T_robot_hand,
            pregrasp_height_m=pregrasp_height_m,
            opening_m=aperture_m,
            closing_direction=best.T_robot_hand[:3, 0].copy(),
            reason=f"none of {len(ranked)} grasps is feasible ({count} of them: {reason})",
            score=0.0,
            candidates=summaries,
        )
    return GraspPlan(
        gripper=gripper,
        status="ok",
        T_robot_hand=best.T_robot_hand,
        pregrasp_height_m=pregrasp_height_m,
        opening_m=best.opening_m,
        closing_direction=best.T_robot_hand[:3, 0].copy(),
        predicted_contacts=best.predicted_contacts,
        spread_rad=best.spread_rad,
        score=best.summary.score,
        candidates=summaries,
    )


def feasible_plans(
    gripper: str, candidates: list[Candidate], pregrasp_height_m: float, aperture_m: float
) -> tuple[GraspPlan, ...]:
    """Every feasible candidate as a plan of its own, best first (the choices of a next
    grasp, :mod:`pipeline.next_grasp`)."""
    feasible = sorted((c for c in candidates if c.summary.feasible), key=lambda c: -c.summary.score)
    return tuple(
        plan_from_candidates(gripper, [c], pregrasp_height_m, aperture_m) for c in feasible
    )


class CandidatePlanner(GraspPlanner):
    """A planner that ranks candidates: its feasible ones are the alternatives a next grasp
    is chosen among, whatever its ``strategy``. A subclass provides ``_check_hand`` (raise
    :class:`~pipeline.errors.ConfigError` for a hand it cannot plan for) and
    ``_candidates`` (every candidate it considers on the cloud)."""

    @abstractmethod
    def _check_hand(self, gripper: GripperSpec) -> None: ...

    @abstractmethod
    def _candidates(
        self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec
    ) -> list[Candidate]: ...

    def alternatives(
        self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec
    ) -> tuple[GraspPlan, ...]:
        self._check_hand(gripper)
        return feasible_plans(
            gripper.name,
            self._candidates(cloud, proposal, gripper),
            self.params.pregrasp_height_m,
            gripper.max_aperture_m,
        )
