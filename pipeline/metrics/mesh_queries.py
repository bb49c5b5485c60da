"""Where lines parallel to a coordinate axis cross a triangle mesh, in numpy
(docs/method.md §6): the inside tests of the evaluation's solids and IoU.

Crossings are counted once per crossing even where a line meets an edge or a vertex that
triangles share: a point on an edge belongs to exactly one of the two triangles that share
it (the edge's test is the same number for both, with opposite signs, and a tie goes to
the side the edge's direction names, as rasterisers do), so the parity of a ray's
crossings of a closed mesh says whether its start lies inside.
"""

from __future__ import annotations

import numpy as np


def grid_crossings(
    triangles: np.ndarray, axis: int, low: np.ndarray, pitch: float, counts: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Where lines parallel to coordinate ``axis`` cross a triangle mesh.

    The lines pass through the points of a regular grid across the axis: the two other
    coordinates (in increasing order of their index) are ``low + pitch * (i, j)`` for
    ``0 <= i < counts[0]``, ``0 <= j < counts[1]``. Returns every crossing's line index
    ``i * counts[1] + j`` and the crossing's coordinate along ``axis`` (m), unordered.
    Triangles parallel to the axis are never crossed (their neighbours are).

    Each triangle is tested against the lines of its bounding rectangle; along each row
    ``i`` of a triangle whose rectangle holds more than :data:`_FEW_LINES` lines, only
    against those within a pitch of the span its edges give the second coordinate there
    (a long thin triangle across the grid's diagonal, such as a fan of a cylinder's cap,
    covers a few of its rectangle's hundreds of lines).

    Args:
        triangles: ``(F, 3, 3)`` the corners of each triangle (m).
        axis: 0, 1 or 2.
        low: ``(2,)`` the grid's first point across the axis (m).
        pitch: the grid's spacing (m).
        counts: the grid's lines along each of the two other coordinates.
    """
    across = [k for k in range(3) if k != axis]
    u, v = triangles[:, :, across[0]], triangles[:, :, across[1]]
    # The grid lines inside each triangle's bounding rectangle, row by row.
    u_low, u_high = u.min(axis=1), u.max(axis=1)
    first_i = np.clip(np.ceil((u_low - low[0]) / pitch), 0, counts[0]).astype(np.int64)
    last_i = np.clip(np.floor((u_high - low[0]) / pitch), -1, counts[0] - 1).astype(np.int64)
    first_j = np.clip(np.ceil((v.min(axis=1) - low[1]) / pitch), 0, counts[1]).astype(np.int64)
    last_j = np.clip(np.floor((v.max(axis=1) - low[1]) / pitch), -1, counts[1] - 1)
    width_i = np.maximum(last_i - first_i + 1, 0)
    width_j = np.maximum(last_j.astype(np.int64) - first_j + 1, 0)
    owner, i = _ragged(first_i, width_i)
    row_first, row_last = first_j[owner], last_j[owner].astype(np.int64)
    # Along the rows of large triangles: the triangle's span in v at the row's u (clamped
    # to the triangle's span in u against rounding), widened by a pitch each side.
    large = np.flatnonzero((width_i * width_j > _FEW_LINES)[owner])
    if len(large):
        k = owner[large]
        row_u = np.clip(low[0] + pitch * i[large], u_low[k], u_high[k])
        v_low, v_high = _row_span(u[k], v[k], row_u)
        row_first[large] = np.maximum(row_first[large], np.ceil((v_low - low[1]) / pitch - 1.0))
        row_last[large] = np.minimum(row_last[large], np.floor((v_high - low[1]) / pitch + 1.0))
    row, j = _ragged(row_first, np.maximum(row_last - row_first + 1, 0))
    owner, i = owner[row], i[row]
    points = np.column_stack([low[0] + pitch * i, low[1] + pitch * j])
    line, height = _crossings(triangles, owner, axis, points)
    return (i * counts[1] + j)[line], height


#: A triangle whose bounding rectangle holds at most this many grid lines is tested against
#: all of them (finding its span along each row would cost more than the tests it saves).
_FEW_LINES = 8


def _row_span(u: np.ndarray, v: np.ndarray, row_u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least and greatest ``v`` where the line ``u = row_u[k]`` meets triangle ``k``'s
    edges (``u``, ``v``: ``(K, 3)`` its corners); an edge along the line gives both its
    ends."""
    v_low = np.full(len(row_u), np.inf)
    v_high = np.full(len(row_u), -np.inf)
    for start, end in ((0, 1), (1, 2), (2, 0)):
        u0, u1, v0, v1 = u[:, start], u[:, end], v[:, start], v[:, end]
        meets = (np.minimum(u0, u1) <= row_u) & (row_u <= np.maximum(u0, u1))
        span = u1 - u0
        t = np.clip(np.divide(row_u - u0, span, out=np.zeros_like(span), where=span != 0.0), 0, 1)
        at = v0 + t * (v1 - v0)
        along = span == 0.0
        v_low = np.where(meets, np.minimum(v_low, np.where(along, np.minimum(v0, v1), at)), v_low)
        v_high = np.where(
            meets, np.maximum(v_high, np.where(along, np.maximum(v0, v1), at)), v_high
        )
    return v_low, v_high


def ray_crossings(
    triangles: np.ndarray, starts: np.ndarray, axis: int
) -> tuple[np.ndarray, np.ndarray]:
    """Where rays from the ``(N, 3)`` points ``starts`` along ``+axis`` cross a triangle
    mesh (``(F, 3, 3)`` corners, m): every crossing's ray index and its coordinate along
    ``axis`` (m), unordered. A crossing exactly at the start does not count."""
    across = [k for k in range(3) if k != axis]
    order = np.argsort(starts[:, across[0]], kind="stable")
    sorted_u = starts[order, across[0]]
    first = np.searchsorted(sorted_u, triangles[:, :, across[0]].min(axis=1), side="left")
    last = np.searchsorted(sorted_u, triangles[:, :, across[0]].max(axis=1), side="right")
    owner, index = _ragged(first, last - first)
    ray = order[index]
    v = starts[ray, across[1]]
    near = (v >= triangles[owner, :, across[1]].min(axis=1)) & (
        v <= triangles[owner, :, across[1]].max(axis=1)
    )
    owner, ray = owner[near], ray[near]
    hits, height = _crossings(triangles, owner, axis, starts[ray][:, across])
    ahead = height > starts[ray[hits], axis]
    return ray[hits][ahead], height[ahead]


def _ragged(first: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Runs ``first[k], first[k] + 1, ... first[k] + count[k] - 1`` one after another: each
    entry's run ``k`` and value."""
    owner = np.repeat(np.arange(len(count)), count)
    starts = np.cumsum(count) - count
    return owner, first[owner] + np.arange(len(owner)) - starts[owner]


def _crossings(
    triangles: np.ndarray, owner: np.ndarray, axis: int, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Which of the pairs (triangle ``owner[k]``, the line through ``points[k]`` (the two
    other coordinates) along ``axis``) cross, and where: the indices of the crossing pairs
    and their coordinates along ``axis``."""
    across = [k for k in range(3) if k != axis]
    u, v, w = (triangles[:, :, k] for k in (*across, axis))
    # What depends on a triangle's edges alone: once for each triangle a pair has.
    taken = np.zeros(len(triangles), dtype=bool)
    taken[owner] = True
    row = (np.cumsum(taken) - 1)[owner]
    edges = _edges(u[taken], v[taken])
    (start_u, start_v, du, dv, flip), tie = (np.take(a, row, axis=-1) for a in edges)
    weights = [
        (du[e] * (points[:, 1] - start_v[e]) - dv[e] * (points[:, 0] - start_u[e])) * flip[e]
        for e in range(3)
    ]
    area = weights[0] + weights[1] + weights[2]
    # Facing the other way: the same tests mirrored (an edge's tie then goes to the other
    # side, as the edge runs the other way round this triangle).
    sign = np.sign(area)
    inside = sign != 0.0
    for value, edge_tie in zip(weights, tie, strict=True):
        value = value * sign
        inside &= (value > 0.0) | ((value == 0.0) & (edge_tie == (sign > 0.0)))
    hits = np.flatnonzero(inside)
    e0, e1, e2 = (value[hits] for value in weights)
    at = w[owner[hits]]
    height = (e0 * at[:, 0] + e1 * at[:, 1] + e2 * at[:, 2]) / area[hits]
    return hits, height


def _edges(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edges opposite each corner of every triangle (corners ``(F, 3)`` ``u``, ``v``
    across the axis), ``(5, 3, F)``: each edge's start ``u``, ``v``, its run ``du``,
    ``dv`` and a sign, and ``(3, F)`` whether a point on the edge counts as inside for a
    triangle that goes round counter-clockwise.

    Twice the signed area of triangle (edge start, edge end, point ``p``) is
    ``sign (du (p_v - v) - dv (p_u - u))``: the edge is taken from its lesser endpoint, so
    the two triangles sharing an edge get exactly opposite numbers; the tie goes to the
    triangle for which the edge runs downward in ``v`` (or, level, towards lesser ``u``),
    which is exactly one of the two.
    """
    u0, v0 = u[:, [1, 2, 0]].T, v[:, [1, 2, 0]].T
    u1, v1 = u[:, [2, 0, 1]].T, v[:, [2, 0, 1]].T
    swap = (u0 > u1) | ((u0 == u1) & (v0 > v1))
    start_u, start_v = np.where(swap, u1, u0), np.where(swap, v1, v0)
    du, dv = np.where(swap, u0, u1) - start_u, np.where(swap, v0, v1) - start_v
    tie = (v1 < v0) | ((v1 == v0) & (u1 < u0))
    return np.stack([start_u, start_v, du, dv, np.where(swap, -1.0, 1.0)]), tie
