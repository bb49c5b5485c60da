"""What every grasp candidate shares: the evaluated :class:`Candidate`, its settings and
parameters, the frame candidates are enumerated on (:func:`candidate_frame`) and the score.

A candidate closes along a horizontal direction at an angle from the proposed symmetry
plane's normal, with its pads' centres at a height, on the cloud completed by mirroring
it through the proposed plane (moved back if needed to cover every visible point,
:func:`covering_plane`). It is *feasible* when the hand can descend around the object
without touching it (its opened fingers and palm clear every cloud point above the
fingertips), close without touching it other than with its pads, and every pad meets a
side (not only an edge or the top) with the fingertips above the table. Its score, in
[0, 1], multiplies three factors:

* *contact*: the smallest predicted pad contact quality over the fingers
  (:attr:`~pipeline.planning.pad_contact.PadContact.quality`, from
  :func:`~pipeline.planning.pad_contact.pad_coverage`): each finger must meet the
  surface squarely with its pad, so the grasp has contacts on opposing sides - a pad over
  a rim, a cap or an edge covers little, a pad grazing a curved side meets it inclined;
* *alignment* ``(1 + |cos angle|) / 2``: closing along the plane normal puts contacts on
  the visible front and the hidden back, which is what the estimator learns most from;
* *stability* ``1 / (1 + w h / f)``: the contact height ``h`` above the table over the
  object's half-footprint ``f`` along the closing direction is the lever of any residual
  push of the fingers; lower grasps on a wider footprint tip less (``w``: the planner's
  ``tipping_weight``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from pipeline.params import param
from pipeline.planning.grasp_geometry import front_to_back
from pipeline.planning.order_statistics import percentiles
from pipeline.types import GraspCandidate, PadLayout, SymmetryPlane

#: Fewest cloud points inside a part of the hand that make a collision: fewer are taken
#: for depth noise and mixed pixels at the object's silhouette (about 2 mm apart, a real
#: overlap of 5 x 5 mm holds more).
MIN_HITS = 8
#: Why a grasp is rejected when a pad would stop beyond the object's centre: the completed
#: model has no surface on that pad's side under it (a hole where the camera saw nothing to
#: mirror), so what the pad would meet is the far side, from inside.
BEYOND_CENTRE = "a pad would pass the object's centre: the model has no surface before it"
#: The share of its score a parallel-jaw grasp keeps when the back pad would pass the
#: object's centre (:data:`BEYOND_CENTRE`): that pad's contact is unknown, so the grasp is
#: scored by the front pad's contact alone, below grasps whose pads both meet the model
#: unless they score ten times less.
BLIND_PAD_FACTOR = 0.1


def covering_plane(
    points_robot: np.ndarray, plane: SymmetryPlane, viewpoint_m: np.ndarray | None = None
) -> SymmetryPlane:
    """``plane`` moved back along its normal, if needed, so that the cloud mirrored through
    it reaches the farthest visible point: at least midway between the nearest and the
    farthest visible points along the normal (1st and 99th percentiles), seen from the
    visible side (the camera at ``viewpoint_m``, frame R, when known). A plane through the
    cloud's centroid (PCA) lies too close to the camera when the view also sees the
    object's top reaching far back; the completed object then ends before a top it must
    hold up."""
    normal = plane.normal
    along = points_robot @ normal
    middle = float(np.mean(np.percentile(along, [1.0, 99.0])))
    backward = front_to_back(points_robot, normal, viewpoint_m) @ normal > 0.0
    offset = max(plane.offset_m, middle) if backward else min(plane.offset_m, middle)
    return SymmetryPlane(plane.theta_rad, offset)


def alignment(angle_rad: float) -> float:
    """The score's alignment factor of a grasp closing ``angle_rad`` from the plane normal:
    1 along the normal, 1/2 along the plane."""
    return (1.0 + abs(math.cos(angle_rad))) / 2.0


def candidate_score(
    coverages: tuple[float, ...], angle_rad: float, tipping_ratio: float, tipping_weight: float
) -> float:
    """The module docstring's score: contact x alignment x stability, in [0, 1]."""
    return min(coverages) * alignment(angle_rad) / (1.0 + tipping_weight * tipping_ratio)


def footprint_half_m(completed_robot: np.ndarray, direction: np.ndarray) -> float:
    """Half the object's extent along ``direction`` (2nd to 98th percentile), m."""
    low, high = percentiles(completed_robot @ direction, (2.0, 98.0))
    return max((high - low) / 2.0, 1e-3)


def height_grid(low_m: float, high_m: float, step_m: float) -> np.ndarray:
    """Pad-centre heights from ``high_m`` down to ``low_m`` (inclusive), ``step_m`` apart;
    only ``low_m`` when the range is empty."""
    if high_m <= low_m:
        return np.array([low_m])
    heights = high_m - step_m * np.arange(math.floor((high_m - low_m) / step_m + 1e-9) + 1)
    return heights if heights[-1] <= low_m + 1e-9 else np.append(heights, low_m)


class CandidateCloud:
    """The clouds every candidate of one plan is evaluated on (frame R, m), with what many
    candidates share computed once: the points in a height range (a pad's rows at one
    height), the points above a height (for counts and order statistics)
    and its half-footprint along a closing direction.

    Attributes:
        visible: ``(N, 3)`` the segmented cloud.
        completed: ``(M, 3)`` the visible cloud and its mirror image.
    """

    def __init__(self, visible: np.ndarray, completed: np.ndarray) -> None:
        self.visible = visible
        self.completed = completed
        self._by_height = {
            seen: points.take(np.argsort(points[:, 2], kind="stable"), axis=0)
            for seen, points in ((True, visible), (False, completed))
        }
        self._slabs: dict[tuple[bool, float, float], np.ndarray] = {}
        self._bands: dict[tuple[float, float], np.ndarray] = {}
        self._footprints: dict[tuple[float, ...], float] = {}
        self._offsets: dict[tuple[bool, bytes, bytes], np.ndarray] = {}

    def slab(self, low_m: float, high_m: float, *, visible: bool = False) -> np.ndarray:
        """The completed (or ``visible``) points with ``low_m <= z <= high_m``, in the
        cloud's order."""
        key = (visible, low_m, high_m)
        if key not in self._slabs:
            points = self.visible if visible else self.completed
            self._slabs[key] = points.compress(
                (points[:, 2] >= low_m) & (points[:, 2] <= high_m), axis=0
            )
        return self._slabs[key]

    def band(self, height_m: float, half_m: float) -> np.ndarray:
        """The completed points with ``|z - height_m| <= half_m``, in the cloud's order."""
        key = (height_m, half_m)
        if key not in self._bands:
            z = self.completed[:, 2]
            self._bands[key] = self.completed.compress(np.abs(z - height_m) <= half_m, axis=0)
        return self._bands[key]

    def above(self, z_m: float, *, visible: bool = False) -> np.ndarray:
        """The completed (or ``visible``) points with ``z >= z_m``, lowest first (not in
        the cloud's order: for counts and order statistics)."""
        by_height = self._by_height[visible]
        return by_height[np.searchsorted(by_height[:, 2], z_m) :]

    def along_above(self, axes: np.ndarray, z_m: float, *, visible: bool = False) -> np.ndarray:
        """``(A, K)``: the horizontal offsets ``axes @ xy`` (``axes`` ``(A, 2)``) of the
        points :meth:`above` returns, in its order.

        Every candidate closing along one direction has the same axes (its fingers'
        facings, the lines across them): the product is taken once for the whole cloud
        and sliced, a row of a matrix product being the same whichever rows stand beside
        it."""
        key = (visible, axes.tobytes(), b"")
        by_height = self._by_height[visible]
        if key not in self._offsets:
            self._offsets[key] = axes @ by_height[:, :2].T
        return self._offsets[key][:, np.searchsorted(by_height[:, 2], z_m) :]

    def offsets_above(
        self, origin_m: np.ndarray, axis: np.ndarray, z_m: float, *, visible: bool = False
    ) -> np.ndarray:
        """``(K,)``: ``(points - origin_m) @ axis`` (both ``(3,)``) of the points
        :meth:`above` returns, in its order; taken once for the whole cloud, as
        :meth:`along_above`."""
        key = (visible, axis.tobytes(), origin_m.tobytes())
        by_height = self._by_height[visible]
        if key not in self._offsets:
            self._offsets[key] = (by_height - origin_m) @ axis
        return self._offsets[key][np.searchsorted(by_height[:, 2], z_m) :]

    def footprint_half_m(self, direction: np.ndarray) -> float:
        """:func:`footprint_half_m` of the completed cloud along ``direction``."""
        key = tuple(direction)
        if key not in self._footprints:
            self._footprints[key] = footprint_half_m(self.completed, direction)
        return self._footprints[key]


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

    @classmethod
    def rejected(
        cls, angle_rad: float, height_m: float, spread_rad: float, reason: str
    ) -> Candidate:
        """An infeasible candidate, and why."""
        return cls(
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

    def below_clearance(self, fingertip_z_m: float) -> bool:
        """Whether a fingertip at ``fingertip_z_m`` lies below ``table_clearance_m`` above
        the table. The lowest pad height tried is that bound itself, which float rounding
        would otherwise put a fraction of a nanometre below it."""
        return fingertip_z_m < self.table_height_m + self.table_clearance_m - _ROUNDING_M


#: Slack of :meth:`CandidateSettings.below_clearance` (m).
_ROUNDING_M = 1e-9


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
        0.004, "candidates: least gap between the descending hand and the cloud (m)", at_least=0.0
    )
    touch_tolerance_m: float = param(
        0.003,
        "candidates: surface within this of a pad at its first touch counts (m)",
        at_least=0.0,
    )
    tipping_weight: float = param(
        0.2, "candidates: weight of the contact height / half-footprint in the score", at_least=0.0
    )
    top_margin_m: float = param(0.005, "pad top edge below the object's top (m)", at_least=0.0)
    table_clearance_m: float = param(
        0.01, "lowest fingertip height above the table (m)", at_least=0.0
    )
    low_table_clearance_m: float = param(
        0.002,
        "candidates: the fingertips' clearance above the table tried when no grasp is "
        "feasible with table_clearance_m, so a low object's sides reach the pads' lowest "
        "taxels; above the table the segmenter measured, when it did (m)",
        at_least=0.0,
    )
    cloud_base_above_table_m: float = param(
        0.02, "the table lies this far below the cloud's lowest point (m)", at_least=0.0
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
    viewpoint_m: np.ndarray | None = None,
) -> CandidateFrame:
    """The completed cloud, and pad-centre heights every ``params.height_step_m`` from the
    lowest allowed - fingertips ``table_clearance_m`` above the table (taken
    ``cloud_base_above_table_m`` below the cloud), and with ``keep_above_cloud`` the lower
    edge of the pad's touching part (``contact_edge_below_centre_m`` below its centre;
    negative above it) above the cloud's bottom - to ``top_margin_m`` below the cloud's top (the
    pads may reach above a short object; their predicted contact says how much of them
    touches). ``viewpoint_m`` is the camera's position (frame R) when known."""
    completed = np.concatenate(
        [points_robot, covering_plane(points_robot, plane, viewpoint_m).mirror(points_robot)]
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
