"""The volume a view leaves hidden under the object's seen surface: points below the seen
points, down to the cloud's bottom, that lie behind the seen surface from the camera.

An object on the table is seen from above and one side; the mirror plane completes the side
it was seen from, but where the camera looks at the object along its plane (a box seen
end-on), the mirror image is the seen face again, and the sides the pads close on are not
in the completed cloud at all. The top the camera did see says how far the object reaches
there: every point under it down to the table is object, or space the camera could not see.
A point the camera could have seen (its ray meets no seen surface before it) is free space
and is left out; so is one under an overhang that the camera saw the table through.
"""

from __future__ import annotations

import math

import numpy as np

#: Seen points within this many of their median angular spacing of a ray count as the
#: surface the ray meets (a pixel's neighbours along a row or a diagonal).
_RAY_SPACINGS = 2.0
#: A hidden point must lie this far behind the seen surface along its ray (m): points on
#: the seen surface itself are in the cloud already, and depth noise puts some a little
#: in front of it.
_BEHIND_M = 0.003


def hidden_below(points_m: np.ndarray, viewpoint_m: np.ndarray, step_m: float) -> np.ndarray:
    """Points ``step_m`` apart in height below the highest seen point of each horizontal
    grid cell ``step_m`` wide, down to the cloud's lowest point (2nd percentile), that
    the camera at ``viewpoint_m`` could not see: along the ray to each, a seen point lies
    at least 3 mm nearer the camera. ``(K, 3)``, frame and metres of ``points_m``
    (``(N, 3)``, the seen cloud); empty when none is hidden.
    """
    if len(points_m) < 2:
        return np.zeros((0, 3))
    cells = np.floor(points_m[:, :2] / step_m).astype(np.int64)
    order = np.lexsort((points_m[:, 2], cells[:, 1], cells[:, 0]))
    cells, ordered = cells[order], points_m[order]
    last = np.append(np.any(np.diff(cells, axis=0) != 0, axis=1), True)
    columns, tops = ordered[last, :2], ordered[last, 2]  # each cell's highest seen point
    bottom = float(np.percentile(points_m[:, 2], 2.0))
    depths = np.floor((tops - bottom) / step_m).astype(np.int64)
    repeat = np.maximum(depths, 0)
    if not np.any(repeat):
        return np.zeros((0, 3))
    index = np.repeat(np.arange(len(columns)), repeat)
    level = np.arange(len(index)) - np.repeat(np.cumsum(repeat) - repeat, repeat) + 1
    candidates = np.column_stack([columns[index], tops[index] - level * step_m])
    return candidates[_behind_seen(points_m, candidates, viewpoint_m)]


def seen_surface(points_m: np.ndarray, viewpoint_m: np.ndarray) -> np.ndarray:
    """The points of ``points_m`` (``(N, 3)``) that no other hides from the camera at
    ``viewpoint_m``: the seen surface of a cloud :func:`hidden_below`'s points were added
    to, for what is measured on the surface (the wall of an open object under its rim,
    :mod:`pipeline.planning.rim`)."""
    if len(points_m) < 2:
        return points_m
    return points_m[~_behind_seen(points_m, points_m, viewpoint_m)]


def _behind_seen(seen_m: np.ndarray, points_m: np.ndarray, viewpoint_m: np.ndarray) -> np.ndarray:
    """Whether each of ``points_m`` lies behind the seen surface from ``viewpoint_m``:
    a seen point on its ray (within :data:`_RAY_SPACINGS` of the cloud's median angular
    spacing) lies :data:`_BEHIND_M` or more nearer the camera."""
    from scipy.spatial import cKDTree  # deferred: planners load with `plugins`

    rays = seen_m - viewpoint_m
    seen_range = np.linalg.norm(rays, axis=1)
    tree = cKDTree(rays / seen_range[:, None])
    spacing, _ = tree.query(rays / seen_range[:, None], k=2)
    tolerance = _RAY_SPACINGS * float(np.median(spacing[:, 1]))
    offsets = points_m - viewpoint_m
    ranges = np.linalg.norm(offsets, axis=1)
    k = max(1, math.ceil(_RAY_SPACINGS) ** 2 * 4)
    distance, neighbour = tree.query(offsets / ranges[:, None], k=k, distance_upper_bound=tolerance)
    found = np.isfinite(distance)
    nearest = np.where(found, seen_range[np.minimum(neighbour, len(seen_m) - 1)], np.inf)
    return nearest.min(axis=1) <= ranges - _BEHIND_M
