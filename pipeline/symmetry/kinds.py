"""The kind of symmetry one view supports: the paper's vertical plane, a rotation axis, or a
mirror plane of any orientation.

Each kind completes the view its own way (:func:`complete`): a plane mirrors the cloud, an
axis sweeps the visible profile about itself. The camera judges both completions alike: the
share of completed points it saw free space at (in front of the measured surface by more
than a tolerance, :func:`pipeline.perception.visibility.free_space_depths`). An axis must
also fit: its slices must be circles to within ``max_profile_rms_m``
(:mod:`pipeline.symmetry.axis_fit`), else it is not a candidate (a box's corner, a mug's
visible handle). The axis is chosen when it fits and its completion has no larger share of
points in free space than the plane's plus ``margin``: both make the same number of
assumptions about the hidden side (two parameters each), and the sweep says more about it.
When the axis fits the body but its sweep is refuted, the points off the axis are a part
(a mug's handle): the plane through the axis and that part is proposed when the camera
accepts it as well as the best plane. An axis of any direction (a body of revolution lying
on its side, :func:`pipeline.symmetry.axis_fit.fit_any_axis`) is judged like the vertical
one, its sweep also refuted below the table, after the camera has settled its direction
(:func:`settled_axis`), with a penalty for its two further parameters. A plane of any
orientation (:mod:`pipeline.symmetry.plane_search`) is judged the same way, its mirror image
also refuted where it falls below the table, and chosen over the level choice only when its
completion is refuted less by more than a margin, the penalty for its third parameter: an
upright object keeps its vertical plane.

Pure numeric but for the depth image it is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from pipeline.perception.visibility import free_space_depths
from pipeline.symmetry.axis_fit import (
    SLICE_M,
    AxisFit,
    fit_any_axis,
    fit_axis,
    profile_residuals,
    tilt_deg,
)
from pipeline.symmetry.plane_search import PlaneFit, best_plane, table_top
from pipeline.types import DepthObservation, Symmetry, SymmetryPlane

#: Turns of the visible profile a sweep completion holds (the view itself among them).
SWEEP_TURNS = 12
#: Points of a completion the camera checks (an even subsample).
CHECK_POINTS = 3000


@dataclass(frozen=True)
class KindChoice:
    """The kind chosen and the evidence.

    Attributes:
        symmetry: the chosen symmetry (``"vertical-plane"``, ``"axis"`` or ``"plane"``),
            frame R.
        plane: the vertical plane: the chosen one, for an axis the one through it facing
            the camera (:func:`plane_through_axis`; the estimator fuses it), for a leaning
            plane the vertical one :attr:`level` chose (the estimator fuses the leaning
            one; estimators that take vertical planes only take this).
        scores: kind -> share of its completion in seen free space or below the table (inf
            for an axis that does not fit); lower is better.
        axis_fit: the vertical axis fit, None when the view had too few slices.
        level: the choice between the vertical plane and the vertical axis alone, as
            before planes of any orientation were searched.
        plane_fit: the best plane of any orientation, None when none was searched.
        tilted_fit: the axis fit of any direction when it was a candidate (more than
            :data:`MIN_TILT_DEG` from the vertical, its profile within the limit), else
            None.
    """

    symmetry: Symmetry
    plane: SymmetryPlane
    scores: dict[str, float]
    axis_fit: AxisFit | None
    level: Symmetry | None = None
    plane_fit: PlaneFit | None = None
    tilted_fit: AxisFit | None = None

    @property
    def axis(self) -> Symmetry | None:
        """The axis candidate the view was judged on: the tilted one when there was one,
        else the vertical fit's (None without either)."""
        fit = self.tilted_fit or self.axis_fit
        return None if fit is None else fit.axis


def sweep(points_m: np.ndarray, axis: Symmetry, turns: int = SWEEP_TURNS) -> np.ndarray:
    """``(turns * N, 3)`` the points turned about the axis by ``turns`` even steps of a full
    turn (the first step is the points themselves)."""
    return np.vstack([axis.apply(points_m, 2.0 * math.pi * k / turns) for k in range(turns)])


def complete(points_m: np.ndarray, symmetry: Symmetry, table_z_m: float = -math.inf) -> np.ndarray:
    """The completed model of a view: the points and their mirror image for a plane, the
    swept profile for an axis, without the swept points below the table top ``table_z_m``
    (a vertical axis' sweep keeps every point's height; a lying body's sweeps through
    the table where the body rests on it)."""
    if symmetry.is_plane:
        return np.vstack([points_m, symmetry.apply(points_m)])
    swept = sweep(points_m, symmetry)
    return swept[swept[:, 2] >= table_z_m]


def free_space_share(
    model_m: np.ndarray,
    view: DepthObservation,
    tolerance_m: float,
    table_z_m: float = -math.inf,
) -> float:
    """Share of the model's points (an even subsample) lying more than ``tolerance_m`` in
    front of the surface the camera measured on their ray, or more than ``tolerance_m``
    below the table top ``table_z_m`` (a vertical plane's mirror image and a vertical
    axis' sweep keep every point's height; a leaning plane may throw points into the
    table)."""
    sample = model_m[:: max(1, len(model_m) // CHECK_POINTS)]
    return _refuted_share(sample, view, tolerance_m, table_z_m)


def swept_share(
    points_m: np.ndarray,
    axis: Symmetry,
    view: DepthObservation,
    tolerance_m: float,
    table_z_m: float = -math.inf,
) -> float:
    """``free_space_share(sweep(points_m, axis), ...)`` without turning the points the check
    leaves out: the same even subsample of the sweep, each point turned on its own (a
    view of tens of thousands of points swept twelve times, to check three thousand)."""
    count = len(points_m)
    index = np.arange(0, SWEEP_TURNS * count, max(1, SWEEP_TURNS * count // CHECK_POINTS))
    turn, row = np.divmod(index, count)
    sample = np.empty((len(index), 3))
    for k in np.unique(turn):
        chosen = turn == k
        sample[chosen] = axis.apply(points_m[row[chosen]], 2.0 * math.pi * k / SWEEP_TURNS)
    return _refuted_share(sample, view, tolerance_m, table_z_m)


def _refuted_share(
    sample: np.ndarray, view: DepthObservation, tolerance_m: float, table_z_m: float
) -> float:
    """Share of ``sample`` in seen free space or below the table (:func:`free_space_share`)."""
    depths = free_space_depths(sample, view.depth_m, view.intrinsics, view.T_robot_camera)
    return float(np.mean((depths > tolerance_m) | (sample[:, 2] < table_z_m - tolerance_m)))


def plane_through_axis(axis: Symmetry, camera_m: np.ndarray) -> SymmetryPlane:
    """A vertical plane through the axis (the estimator fuses a plane; every plane through
    the axis of a body of revolution is a mirror plane): for a vertical axis the one facing
    the camera, whose mirror image of the seen front is the hidden back; for any other the
    one vertical plane that contains it (a can lying on its side: the plane through its
    axis and the vertical)."""
    level = np.cross(axis.direction, [0.0, 0.0, 1.0])
    if np.linalg.norm(level[:2]) > 1e-9:
        normal = level[:2] / np.linalg.norm(level[:2])
        return SymmetryPlane.from_normal(normal, float(normal @ axis.point_m[:2]))
    view = axis.point_m[:2] - np.asarray(camera_m)[:2]
    return SymmetryPlane.from_normal(view, float(view @ axis.point_m[:2]))


def choose_kind(
    points_m: np.ndarray,
    view: DepthObservation,
    plane: SymmetryPlane,
    *,
    tolerance_m: float,
    max_profile_rms_m: float,
    margin: float,
    plane_margin: float | None = None,
    max_offset_m: float = 0.06,
    tilt_margin: float | None = None,
) -> KindChoice:
    """The kind of symmetry the view of ``points_m`` (frame R) supports best.

    Args:
        plane: the best vertical plane (VC's).
        tolerance_m: how far in front of the measured surface a completed point may lie.
        max_profile_rms_m: the largest profile RMS of an axis candidate (m).
        margin: how much larger a share of free-space points the axis completion may have
            than the plane's and still be chosen.
        plane_margin: None: planes of other orientations are not searched. Else the best
            plane of any orientation (:func:`pipeline.symmetry.plane_search.best_plane`)
            is chosen when it leans and its completion's share is lower than the level
            choice's by more than this: the penalty for its third parameter.
        max_offset_m: the plane search's largest shift from the centroid (m).
        tilt_margin: None: axes are vertical. Else, when the level choice is not the
            vertical axis, an axis of any direction
            (:func:`pipeline.symmetry.axis_fit.fit_any_axis`) more than
            :data:`MIN_TILT_DEG` from the vertical and within ``max_profile_rms_m`` is a
            candidate, its sweep also refuted below the table, and it is chosen when its
            share is at most the level choice's plus ``margin`` minus this: the penalty
            for its two further parameters.
    """
    level = _level_kind(points_m, view, plane, tolerance_m, max_profile_rms_m, margin)
    level = replace(level, level=level.symmetry)
    table_z = table_top(points_m, view)
    if tilt_margin is not None and level.symmetry.kind != "axis":
        level = _tilted_kind(
            points_m, view, level, tolerance_m, max_profile_rms_m, margin - tilt_margin, table_z
        )
    if plane_margin is None:
        return level
    fit = best_plane(points_m, view, tolerance_m=tolerance_m, max_offset_m=max_offset_m)
    scores = {
        **level.scores,
        "plane": free_space_share(complete(points_m, fit.symmetry), view, tolerance_m, table_z),
    }
    if fit.symmetry.kind == "plane" and (
        scores["plane"] + plane_margin < scores[level.symmetry.kind]
    ):
        return replace(level, symmetry=fit.symmetry, scores=scores, plane_fit=fit)
    return replace(level, scores=scores, plane_fit=fit)


#: An axis of any direction is a candidate beside the vertical fit when it is farther than
#: this from the vertical (deg): nearer, the vertical fit is the better (two parameters
#: fewer) description, and the level choice has judged it.
MIN_TILT_DEG = 5.0


def _tilted_kind(
    points_m, view, level, tolerance_m, max_profile_rms_m, margin, table_z_m
) -> KindChoice:
    """``level`` (the level choice, not an axis), or the axis of any direction when it is a
    candidate and its sweep's share of points in seen free space or below the table is at
    most the level choice's plus ``margin`` (:func:`choose_kind`)."""
    fit = fit_any_axis(points_m)
    if fit is None or tilt_deg(fit.axis) <= MIN_TILT_DEG or fit.profile_rms_m > max_profile_rms_m:
        return level
    fit, share = settled_axis(points_m, view, fit, tolerance_m, table_z_m)
    if tilt_deg(fit.axis) <= MIN_TILT_DEG or fit.profile_rms_m > max_profile_rms_m:
        return level
    scores = {**level.scores, "axis": share}
    if share <= level.scores[level.symmetry.kind] + margin:
        camera = np.asarray(view.T_robot_camera)[:3, 3]
        plane = plane_through_axis(fit.axis, camera)
        return replace(level, symmetry=fit.axis, plane=plane, scores=scores, tilted_fit=fit)
    return replace(level, scores=scores, tilted_fit=fit)


def vc_kind(
    points_m: np.ndarray, view: DepthObservation, plane: SymmetryPlane, params: Any
) -> KindChoice:
    """:func:`choose_kind` with VC's parameters: ``params`` holds ``tolerance_m``,
    ``max_profile_rms_m``, ``kind_margin``, ``plane_margin`` (1: no leaning planes),
    ``tilt_margin`` (1: vertical axes only) and ``max_offset_m`` (the ``vc`` initialiser's
    ``Params``)."""
    return choose_kind(
        points_m,
        view,
        plane,
        tolerance_m=params.tolerance_m,
        max_profile_rms_m=params.max_profile_rms_m,
        margin=params.kind_margin,
        plane_margin=params.plane_margin if params.plane_margin < 1.0 else None,
        max_offset_m=params.max_offset_m,
        tilt_margin=params.tilt_margin if params.tilt_margin < 1.0 else None,
    )


def _level_kind(points_m, view, plane, tolerance_m, max_profile_rms_m, margin) -> KindChoice:
    """:func:`choose_kind` between the vertical plane and the vertical axis alone."""
    vertical = Symmetry.from_plane(plane)
    scores = {"vertical-plane": free_space_share(complete(points_m, vertical), view, tolerance_m)}
    fit = fit_axis(points_m)
    if fit is None or fit.profile_rms_m > max_profile_rms_m:
        scores["axis"] = math.inf
        return KindChoice(vertical, plane, scores, fit)
    scores["axis"] = swept_share(points_m, fit.axis, view, tolerance_m)
    if scores["axis"] <= scores["vertical-plane"] + margin:
        camera = np.asarray(view.T_robot_camera)[:3, 3]
        return KindChoice(fit.axis, plane_through_axis(fit.axis, camera), scores, fit)
    # The body fits the axis but its sweep is refuted: a part off the axis (a handle, a
    # spout) the sweep threw into free space. Its plane is the one through the axis and
    # that part, when the camera accepts it as well as the best plane.
    through = plane_through_part(points_m, fit)
    if through is not None:
        share = free_space_share(complete(points_m, through), view, tolerance_m)
        if share <= scores["vertical-plane"] + margin:
            scores["vertical-plane"] = share
            normal = through.direction[:2]
            return KindChoice(
                through, SymmetryPlane.from_normal(normal, through.offset_m), scores, fit
            )
    return KindChoice(vertical, plane, scores, fit)


#: The first and the last step of :func:`settled_axis`'s turns of the direction (rad).
SETTLE_STEPS_RAD = (math.radians(4.0), math.radians(1.0))


def settled_axis(
    points_m: np.ndarray,
    view: DepthObservation,
    fit: AxisFit,
    tolerance_m: float,
    table_z_m: float,
) -> tuple[AxisFit, float]:
    """The axis near ``fit``'s direction whose sweep the camera refutes least, and that
    share (:func:`free_space_share` with the table).

    The profile cannot settle a lying body's direction: seen over part of its turn (the
    table and the body itself hide the rest), an axis tilted toward the seen side with the
    slices' radii growing along it fits the view about as well as the true one (a
    cylinder taken for a cone), and the fits of lying cans were 4-7 deg off. The tilted
    sweep puts one end into the table and the other into seen free space, so the camera
    settles it: from the fit's direction, the eight directions a step away around it are
    tried (each with its best across coordinates, :func:`fit_axis` along it), the best
    taken when its sweep is refuted less (then by its profile RMS), else the step halved,
    from 4 deg down to 1 deg."""

    def judged(direction: np.ndarray) -> tuple[tuple[float, float], AxisFit | None]:
        along = fit_axis(points_m, direction)
        if along is None:
            return (math.inf, math.inf), None
        share = swept_share(points_m, along.axis, view, tolerance_m, table_z_m)
        return (share, along.profile_rms_m), along

    best = judged(fit.axis.direction)
    if best[1] is None:
        share = swept_share(points_m, fit.axis, view, tolerance_m, table_z_m)
        return fit, share
    step, last = SETTLE_STEPS_RAD
    while step >= last * (1.0 - 1e-9):
        around = [judged(direction) for direction in _ring(best[1].axis, step)]
        nearest = min(around, key=lambda item: item[0])
        if nearest[0] < best[0]:
            best = nearest
        else:
            step /= 2.0
    (share, _), settled = best
    return settled, share


def _ring(axis: Symmetry, step_rad: float) -> list[np.ndarray]:
    """The eight directions ``step_rad`` from the axis', evenly around it (the first along
    its first across axis: :meth:`~pipeline.types.Symmetry.across_axes`)."""
    u, v = axis.across_axes()
    turns = np.arange(8) * math.pi / 4.0
    return [
        math.cos(step_rad) * axis.direction
        + math.sin(step_rad) * (math.cos(turn) * u + math.sin(turn) * v)
        for turn in turns
    ]


#: Points farther than this many profile RMS from their slice's radius lie off the axis.
OFF_AXIS_RMS = 4.0
#: Least share of the view off the axis that makes a part (a handle) rather than noise.
MIN_PART_SHARE = 0.02


def plane_through_part(points_m: np.ndarray, fit: AxisFit) -> Symmetry | None:
    """The vertical plane through the fitted axis and the view's points off it (more than
    :data:`OFF_AXIS_RMS` profile RMS outside their slice's radius), or None when fewer
    than :data:`MIN_PART_SHARE` of the points are off it."""
    residuals = profile_residuals(points_m, fit.axis.direction, fit.axis.point_m, SLICE_M, 1)
    outside = residuals > OFF_AXIS_RMS * fit.profile_rms_m
    if np.mean(outside) < MIN_PART_SHARE:
        return None
    towards = points_m[outside].mean(axis=0)[:2] - fit.axis.point_m[:2]
    if np.linalg.norm(towards) == 0.0:
        return None
    normal = np.array([-towards[1], towards[0], 0.0])
    return Symmetry("vertical-plane", normal, fit.axis.point_m)
