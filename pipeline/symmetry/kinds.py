"""The kind of symmetry one view supports: the paper's vertical plane or a vertical axis.

Each kind completes the view its own way (:func:`complete`): a plane mirrors the cloud, an
axis sweeps the visible profile about itself. The camera judges both completions alike: the
share of completed points it saw free space at (in front of the measured surface by more
than a tolerance, :func:`pipeline.perception.visibility.free_space_depths`). An axis must
also fit: its slices must be circles to within ``max_profile_rms_m``
(:mod:`pipeline.symmetry.axis_fit`), else it is not a candidate (a box's corner, a mug's
visible handle). The axis is chosen when it fits and its completion has no larger share of
points in free space than the plane's plus ``margin``: both make the same number of
assumptions about the hidden side (two parameters each), and the sweep says more about it.

Pure numeric but for the depth image it is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..perception.visibility import free_space_depths
from ..types import DepthObservation, Symmetry, SymmetryPlane
from .axis_fit import AxisFit, fit_axis

#: Turns of the visible profile a sweep completion holds (the view itself among them).
SWEEP_TURNS = 12
#: Points of a completion the camera checks (an even subsample).
CHECK_POINTS = 3000


@dataclass(frozen=True)
class KindChoice:
    """The kind chosen and the evidence.

    Attributes:
        symmetry: the chosen symmetry (``"vertical-plane"`` or ``"axis"``), frame R.
        scores: kind -> share of its completion in seen free space (inf for an axis that
            does not fit); lower is better.
        axis_fit: the axis fit, None when the view had too few slices.
    """

    symmetry: Symmetry
    scores: dict[str, float]
    axis_fit: AxisFit | None


def sweep(points_m: np.ndarray, axis: Symmetry, turns: int = SWEEP_TURNS) -> np.ndarray:
    """``(turns * N, 3)`` the points turned about the axis by ``turns`` even steps of a full
    turn (the first step is the points themselves)."""
    return np.vstack([axis.apply(points_m, 2.0 * math.pi * k / turns) for k in range(turns)])


def complete(points_m: np.ndarray, symmetry: Symmetry) -> np.ndarray:
    """The completed model of a view: the points and their mirror image for a plane, the
    swept profile for an axis."""
    if symmetry.is_plane:
        return np.vstack([points_m, symmetry.apply(points_m)])
    return sweep(points_m, symmetry)


def free_space_share(model_m: np.ndarray, view: DepthObservation, tolerance_m: float) -> float:
    """Share of the model's points (an even subsample) lying more than ``tolerance_m`` in
    front of the surface the camera measured on their ray."""
    sample = model_m[:: max(1, len(model_m) // CHECK_POINTS)]
    depths = free_space_depths(sample, view.depth_m, view.intrinsics, view.T_robot_camera)
    return float(np.mean(depths > tolerance_m))


def plane_through_axis(axis: Symmetry, camera_m: np.ndarray) -> SymmetryPlane:
    """The vertical plane through a vertical axis facing the camera: its mirror image of the
    seen front is the hidden back (the estimator fuses a plane; every plane through the axis
    of a body of revolution is a mirror plane)."""
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
) -> KindChoice:
    """The kind of symmetry the view of ``points_m`` (frame R) supports best.

    Args:
        plane: the best vertical plane (VC's).
        tolerance_m: how far in front of the measured surface a completed point may lie.
        max_profile_rms_m: the largest profile RMS of an axis candidate (m).
        margin: how much larger a share of free-space points the axis completion may have
            than the plane's and still be chosen.
    """
    vertical = Symmetry.from_plane(plane)
    scores = {"vertical-plane": free_space_share(complete(points_m, vertical), view, tolerance_m)}
    fit = fit_axis(points_m)
    if fit is None or fit.profile_rms_m > max_profile_rms_m:
        scores["axis"] = math.inf
    else:
        scores["axis"] = free_space_share(sweep(points_m, fit.axis), view, tolerance_m)
    chosen = fit.axis if scores["axis"] <= scores["vertical-plane"] + margin else vertical
    return KindChoice(chosen, scores, fit)
