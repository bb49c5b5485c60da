"""How much of a view its own mirror image meets: the evidence a mirror plane has in the data.

The camera refutes a mirror plane only where the mirror image lies in seen free space
(VC's test, :mod:`pipeline.perception.visibility`). A plane whose mirror image hides
entirely behind the visible surface passes that test without any evidence *for* it: a
laptop's lid seen from behind, mirrored into a tent, is as consistent with the view as a
box. What tells them apart is the part of the view that lies on both sides of the plane:
on a symmetric object seen from anywhere but straight along the plane's normal, some of
the visible surface (a box's top, a can's front) is its own mirror image, so some visible
points have a mirrored point next to them; on an object the plane does not fit, the
visible and mirrored halves meet nowhere.

A body of revolution seen from the front is the exception: the plane through its axis
across the view mirrors the front onto the hidden back, and nothing meets. Its evidence is
the axis' (:mod:`pipeline.symmetry.axis_fit`): the view's slices are circles about an axis
the plane passes through (:func:`axis_supports`).

Pure numeric.
"""

from __future__ import annotations

import numpy as np

from pipeline.types import Symmetry

#: How far from a visible point its mirrored counterpart may lie (m): the depth noise of a
#: Kinect-class sensor at one to two metres, as VC's tolerance.
COUNTERPART_M = 0.01
#: Least share of the visible points with a mirrored counterpart for the data to support
#: a mirror plane (chosen on half of the labelled real scenes and the synthetic views,
#: checked on the other half: docs/results.md).
MIN_MIRROR_SUPPORT = 0.12
#: Visible points (an even subsample) the support is measured on.
SUPPORT_POINTS = 3000
#: Largest profile RMS of a vertical axis fit that makes the view a body of revolution
#: (m): VC's ``max_profile_rms_m`` default (docs/symmetry.md).
MAX_PROFILE_RMS_M = 0.003


def mirror_support(
    points_m: np.ndarray, plane: Symmetry, counterpart_m: float = COUNTERPART_M
) -> float:
    """Share of the visible points (an even subsample of about :data:`SUPPORT_POINTS`)
    with a point of their mirror image in ``plane`` within ``counterpart_m``.

    Args:
        points_m: ``(N, 3)`` the visible cloud, frame R, metres.
        plane: a mirror plane (``is_plane``), frame R.
        counterpart_m: the largest distance of a counterpart (m).

    Returns:
        The share in [0, 1]; 0 for an empty cloud.
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points_m, dtype=np.float64)
    if not plane.is_plane:
        raise ValueError(f"mirror_support needs a mirror plane, not a {plane.kind}")
    if len(points) == 0:
        return 0.0
    sample = points[:: max(1, len(points) // SUPPORT_POINTS)]
    distances, _ = cKDTree(plane.apply(points)).query(sample, distance_upper_bound=counterpart_m)
    return float(np.mean(distances <= counterpart_m))


def axis_supports(points_m: np.ndarray, plane: Symmetry) -> bool:
    """Whether the view fits a vertical axis (profile RMS at most :data:`MAX_PROFILE_RMS_M`)
    that ``plane`` passes within :data:`COUNTERPART_M` of: a body of revolution, for which
    every plane through its axis is a mirror plane."""
    from pipeline.symmetry.axis_fit import fit_axis

    fit = fit_axis(np.asarray(points_m, dtype=np.float64))
    if fit is None or fit.profile_rms_m > MAX_PROFILE_RMS_M:
        return False
    offset = float((fit.axis.point_m - plane.point_m) @ plane.direction)
    return abs(offset) <= COUNTERPART_M
