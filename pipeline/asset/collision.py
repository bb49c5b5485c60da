"""Convex collision parts of a completed model's solid (docs/method.md §12).

The solid is ``|x| <= w(y, z)`` over a map of cells in the (y, z) plane
(:class:`~pipeline.asset.meshing.HalfWidths`), so a block of cells bounds a convex part: the
hull of its cells' boxes. A block is split in two across its longer side until its hull
stands on average no more than :data:`EXCESS_M` (about the sensor's noise) off the solid it
covers, or its cells are :data:`SMALLEST_CELLS` across. The map is first pooled to coarser
cells (their mean half-width over the exact extent of their filled cells), so every part
lies within the solid's bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import ndimage
from scipy.spatial import ConvexHull

from pipeline.asset.meshing import HalfWidths

#: A part's hull may hold this much more than the solid it covers per area of its
#: surface (m): its average distance off the solid.
EXCESS_M = 0.0015
#: Blocks are not split below this many cells across.
SMALLEST_CELLS = 2
#: The map is pooled to cells of about this edge (m) first: a part's shape needs no finer
#: steps than a hand's pads.
PART_CELL_M = 0.005
#: At most this many parts (the largest blocks are split first).
MAX_PARTS = 24


def convex_parts(solid: HalfWidths, bounds: np.ndarray) -> list[trimesh.Trimesh]:
    """Convex, outward-oriented parts whose union covers ``solid`` (object frame), each
    within ``bounds`` (``(2, 3)``, the solid's surface's bounding box: its smoothing rounds
    the outline's ends a little inside the cells the parts are made of)."""
    boxes = _pooled(solid)
    blocks = [_trimmed(boxes, (0, boxes.width.shape[0], 0, boxes.width.shape[1]))]
    done: list[tuple[int, int, int, int]] = []
    while blocks and len(blocks) + len(done) < MAX_PARTS:
        blocks.sort(key=lambda block: _cells(boxes, block))
        block = blocks.pop()
        if _excess(boxes, block) <= EXCESS_M or max(_spans(block)) < 2 * SMALLEST_CELLS:
            done.append(block)
        else:
            blocks.extend(half for half in _halves(boxes, block) if half is not None)
    return [
        trimesh.convex.convex_hull(np.clip(_corners(boxes, block), bounds[0], bounds[1]))
        for block in done + blocks
    ]


@dataclass(frozen=True)
class _Boxes:
    """Boxes ``|x| <= width[j, k]``, ``low[..., 0] <= y <= high[..., 0]``,
    ``low[..., 1] <= z <= high[..., 1]`` per cell of a pooled map; width 0: none."""

    width: np.ndarray
    low: np.ndarray
    high: np.ndarray


def _pooled(solid: HalfWidths) -> _Boxes:
    """The map pooled to cells of about :data:`PART_CELL_M`: each cell's mean half-width
    and the exact extent of its filled cells."""
    factor = max(1, round(PART_CELL_M / solid.cell_m))
    ny, nz = -(-np.array(solid.width.shape) // factor)
    padded = np.zeros((ny * factor, nz * factor))
    padded[: solid.width.shape[0], : solid.width.shape[1]] = solid.width
    blocks = padded.reshape(ny, factor, nz, factor)
    filled = blocks > 0.0
    counts = filled.sum(axis=(1, 3))
    present = counts > 0
    width = np.where(present, blocks.sum(axis=(1, 3)) / np.maximum(counts, 1), 0.0)
    # Smoothed like the surface (over the filled cells only): a hull reaches the largest
    # half-width of its block, and the points' noise would set that.
    weight = ndimage.gaussian_filter(present.astype(float), 1.0, mode="constant")
    smooth = ndimage.gaussian_filter(width, 1.0, mode="constant")
    width = np.where(present, smooth / np.maximum(weight, 1e-12), 0.0)
    rows = filled.any(axis=3)  # (ny, factor, nz): which fine rows of a cell are filled
    columns = filled.any(axis=1)  # (ny, nz, factor)
    first_row, last_row = np.argmax(rows, axis=1), factor - 1 - np.argmax(rows[:, ::-1], axis=1)
    first_column = np.argmax(columns, axis=2)
    last_column = factor - 1 - np.argmax(columns[:, :, ::-1], axis=2)
    j, k = np.meshgrid(np.arange(ny), np.arange(nz), indexing="ij")
    cell, corner = solid.cell_m, solid.corner_m
    low = np.stack(
        [
            corner[0] + cell * (factor * j + first_row),
            corner[1] + cell * (factor * k + first_column),
        ],
        axis=-1,
    )
    high = np.stack(
        [
            corner[0] + cell * (factor * j + last_row + 1),
            corner[1] + cell * (factor * k + last_column + 1),
        ],
        axis=-1,
    )
    # Where the solid ends its surface passes through the centres of its outermost cells
    # (:func:`~pipeline.asset.meshing.surface`), and never below the table: the boxes end
    # a quarter of a cell out, half way there (a box one cell across keeps half a cell: a
    # hull of flat boxes has no volume).
    present = width > 0.0
    edge = np.pad(~present, 1, constant_values=True)
    half = 0.25 * cell
    low[..., 0] += half * edge[:-2, 1:-1]
    high[..., 0] -= half * edge[2:, 1:-1]
    low[..., 1] = np.maximum(low[..., 1] + half * edge[1:-1, :-2], 0.0)
    high[..., 1] -= half * edge[1:-1, 2:]
    return _Boxes(width, low, high)


def _spans(block: tuple[int, int, int, int]) -> tuple[int, int]:
    j0, j1, k0, k1 = block
    return j1 - j0, k1 - k0


def _cells(boxes: _Boxes, block: tuple[int, int, int, int]) -> int:
    j0, j1, k0, k1 = block
    return int(np.count_nonzero(boxes.width[j0:j1, k0:k1]))


def _trimmed(boxes: _Boxes, block: tuple[int, int, int, int]) -> tuple[int, int, int, int] | None:
    """The block shrunk to its filled cells; None when it has none."""
    j0, j1, k0, k1 = block
    filled = boxes.width[j0:j1, k0:k1] > 0.0
    if not filled.any():
        return None
    rows, columns = np.flatnonzero(filled.any(axis=1)), np.flatnonzero(filled.any(axis=0))
    return (
        j0 + int(rows[0]),
        j0 + int(rows[-1]) + 1,
        k0 + int(columns[0]),
        k0 + int(columns[-1]) + 1,
    )


def _halves(boxes: _Boxes, block: tuple[int, int, int, int]) -> list[tuple | None]:
    j0, j1, k0, k1 = block
    if j1 - j0 >= k1 - k0:
        middle = (j0 + j1) // 2
        return [_trimmed(boxes, (j0, middle, k0, k1)), _trimmed(boxes, (middle, j1, k0, k1))]
    middle = (k0 + k1) // 2
    return [_trimmed(boxes, (j0, j1, k0, middle)), _trimmed(boxes, (j0, j1, middle, k1))]


def _corners(boxes: _Boxes, block: tuple[int, int, int, int]) -> np.ndarray:
    """The corners of the block's boxes."""
    j0, j1, k0, k1 = block
    filled = boxes.width[j0:j1, k0:k1] > 0.0
    w = boxes.width[j0:j1, k0:k1][filled]
    low, high = boxes.low[j0:j1, k0:k1][filled], boxes.high[j0:j1, k0:k1][filled]
    return np.concatenate(
        [
            np.column_stack([sx * w, y[:, 0], z[:, 1]])
            for sx in (-1.0, 1.0)
            for y in (low, high)
            for z in (low, high)
        ]
    )


def _excess(boxes: _Boxes, block: tuple[int, int, int, int]) -> float:
    """The block's hull's volume beyond its boxes per area of its surface (m)."""
    j0, j1, k0, k1 = block
    extent = boxes.high[j0:j1, k0:k1] - boxes.low[j0:j1, k0:k1]
    volume = float((2.0 * boxes.width[j0:j1, k0:k1] * extent[..., 0] * extent[..., 1]).sum())
    hull = ConvexHull(_corners(boxes, block))
    return (hull.volume - volume) / hull.area
