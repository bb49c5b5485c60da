"""Convex surface regions of a depth image: objects that touch, stand on each other or hide
each other come apart where their surfaces meet in a concave crease or a depth step.

Two objects in contact meet in a concave crease (a box on a box: the upper box's side
meets the lower one's top at an inside corner), while one object's own faces meet in
convex edges (the top and side of a box, the wall of a can); two objects one behind the
other are apart in depth. The regions here are the connected pixels of an organised
cloud with neither between them, after the idea of locally convex connected patches
(Stein et al., CVPR 2014) applied on the pixel grid, whose neighbours are free.

Every function works on the image grid: ``(H, W, 3)`` points (frame R, metres, NaN where
there is none) and ``(H, W)`` masks.
"""

from __future__ import annotations

import numpy as np

#: Image offsets (rows, cols) along which creases are looked for: the two axes and the two
#: diagonals, so a crease at any angle crosses one of them nearly at right angles.
DIRECTIONS = ((0, 1), (1, 0), (1, 1), (1, -1))


def image_normals(points: np.ndarray, valid: np.ndarray, window_px: int) -> np.ndarray:
    """``(H, W, 3)`` unit normals: the least-variance axis of the valid points in the
    ``window_px`` square about each pixel (NaN where fewer than 3 are valid); their sign
    is arbitrary (the crease test takes differences of normals turned to the camera: see
    :func:`concave_creases`).

    The window sums come from box filters, so the cost does not depend on the window.
    """
    from scipy.ndimage import uniform_filter

    weight = valid.astype(np.float64)
    p = np.where(valid[..., None], points, 0.0)

    def box(image: np.ndarray) -> np.ndarray:
        return uniform_filter(image, size=window_px, mode="constant")

    count = box(weight)
    safe = np.maximum(count, 1e-12)
    mean = np.stack([box(p[..., i]) for i in range(3)], axis=-1) / safe[..., None]
    covariance = np.empty((*points.shape[:2], 3, 3))
    for i in range(3):
        for j in range(i, 3):
            value = box(p[..., i] * p[..., j]) / safe - mean[..., i] * mean[..., j]
            covariance[..., i, j] = covariance[..., j, i] = value
    enough = valid & (count * window_px**2 >= 3.0 - 1e-9)
    normals = np.full(points.shape, np.nan)
    _, vectors = np.linalg.eigh(covariance[enough])
    normals[enough] = vectors[:, :, 0]
    return normals


def concave_creases(
    points: np.ndarray,
    normals: np.ndarray,
    viewpoint: np.ndarray,
    step_px: int,
    min_turn: float,
) -> np.ndarray:
    """``(H, W) bool``: pixels on a concave crease.

    A pixel is on one when, along one of :data:`DIRECTIONS`, the normals ``step_px``
    pixels either side of it (turned toward the ``viewpoint``) turn toward each other:
    ``(n_a - n_b) . (p_a - p_b) / |p_a - p_b| < -min_turn``. On a convex surface the
    normals turn apart (the product is positive, about the angle between them for a
    right-angled edge), on a flat one it is noise about zero.

    Args:
        points: ``(H, W, 3)`` frame R, NaN where none.
        normals: ``(H, W, 3)`` from :func:`image_normals`.
        viewpoint: ``(3,)`` the camera's position in frame R.
        step_px: half the span of pixels the normals are compared across.
        min_turn: how far the normals must turn toward each other (about the angle in
            radians between them, for a right-angled crease).
    """
    facing = np.einsum("hwk,hwk->hw", normals, viewpoint - points)
    oriented = np.where((facing < 0.0)[..., None], -normals, normals)
    height, width = points.shape[:2]
    crease = np.zeros((height, width), dtype=bool)
    s = step_px
    for dr, dc in DIRECTIONS:
        # a = pixel + s (dr, dc), b = pixel - s (dr, dc), for every pixel both lie inside.
        rows = slice(s * abs(dr), height - s * abs(dr))
        cols = slice(s * abs(dc), width - s * abs(dc))
        a = shifted(rows, cols, s * dr, s * dc)
        b = shifted(rows, cols, -s * dr, -s * dc)
        span = points[a] - points[b]
        length = np.linalg.norm(span, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            turn = np.einsum("hwk,hwk->hw", oriented[a] - oriented[b], span) / length
        crease[rows, cols] |= turn < -min_turn
    return crease


def shifted(rows: slice, cols: slice, dr: int, dc: int) -> tuple[slice, slice]:
    """The image window ``rows, cols`` moved by ``dr`` rows and ``dc`` columns."""
    return slice(rows.start + dr, rows.stop + dr), slice(cols.start + dc, cols.stop + dc)


def connected_regions(points: np.ndarray, keep: np.ndarray, max_gap_m: np.ndarray) -> np.ndarray:
    """``(H, W) int`` labels ``0..K-1`` of the connected regions of the ``keep`` pixels
    (-1 elsewhere): 8-neighbours are connected when both are kept and their points lie
    within ``max_gap_m`` (``(H, W)``, at the first pixel of the pair) of each other."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    height, width = keep.shape
    index = np.arange(height * width).reshape(height, width)
    first, second = [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        rows = slice(0, height - dr)
        cols = slice(max(0, -dc), width - max(0, dc))
        other = (slice(dr, height), slice(max(0, dc), width + min(0, dc)))
        gap = np.linalg.norm(points[rows, cols] - points[other], axis=-1)
        linked = keep[rows, cols] & keep[other] & (gap < max_gap_m[rows, cols])
        first.append(index[rows, cols][linked])
        second.append(index[other][linked])
    i, j = np.concatenate(first), np.concatenate(second)
    graph = coo_matrix((np.ones(len(i), dtype=np.int8), (i, j)), shape=(height * width,) * 2)
    _, labels = connected_components(graph, directed=False)
    labels = labels.reshape(height, width)
    # Renumber the kept pixels' components 0..K-1 in the order of their first pixel.
    _, first_pixel, dense = np.unique(labels[keep], return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first_pixel))
    result = np.full((height, width), -1, dtype=np.int64)
    result[keep] = rank[dense]
    return result
