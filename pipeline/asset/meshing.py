"""A watertight surface of a completed model (docs/method.md §12).

The completed model is symmetric about its plane: every point ``p`` has its mirror image
``p'`` in the model and, for an object that every line across the plane meets in one
interval (a box, a bottle, a can, a drill seen from the side), the segment ``p p'`` lies
inside the object. In the object frame (x along the plane's normal, the plane at x = 0, z
up from the table) those segments are centred on x = 0, so their union is one number per
cell of the (y, z) plane: the half-width ``w(y, z)``, the median ``|x|`` of the cell's
points in the outer half of its extent (the wall they show, without the points of a top or
bottom face that cross the cell; a median, because the largest ``|x|`` lies the sensor's
noise outside the wall). Gaps in the map (pixels the camera missed) are filled from their
neighbours, and the rows nearest the table are extended down to it, where the camera could
not see. The solid ``|x| <= w(y, z)`` is cut out of a grid of cells about the sensor's
noise in size by marching cubes, smoothed over one cell; its base is flat on the table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import ndimage

from pipeline.asset.mass import signed_volume

#: Edge of a grid cell (m): about the depth noise of a Kinect at a tabletop's distance, so
#: the one-cell blur smooths no more than the sensor's noise.
CELL_M = 0.003
#: At most this many cells: a larger object gets larger cells.
MAX_CELLS = 400_000
#: Rows whose lowest point is within this of the model's lowest point are extended down to
#: the table: they stand on it. The camera rarely sees the last centimetre above the table
#: (the segmenter cuts it off, the near side hides it); rows higher up overhang.
BASE_BAND_M = 0.01
#: Cells holding fewer points than this share of the median cell are left empty: the
#: sensor's noise scatters single points past the object's outline.
SPARSE_SHARE = 0.25
#: Gaps in the half-width map up to this many cells across are closed from both sides.
GAP_CELLS = 5
#: Blur of the occupancy, in cells (a Gaussian's standard deviation).
BLUR_CELLS = 1.0
#: Smallest distance from the surface a grid value keeps (cells).
NEAR_LEVEL = 2e-3
#: Decimals of a metre the model files keep (a micrometre).
OBJ_DECIMALS = 6
#: Empty cells around the object: room for the blur.
MARGIN_CELLS = int(np.ceil(3 * BLUR_CELLS)) + 1


@dataclass(frozen=True)
class HalfWidths:
    """The solid ``|x| <= width[j, k]`` over cell ``(j, k)`` of the (y, z) plane, object
    frame (metres).

    Attributes:
        width: ``(ny, nz)`` half-widths, 0 outside the object.
        cell_m: the cells' edge.
        corner_m: ``(2,)`` the (y, z) of cell ``(0, 0)``'s lower corner. The table (z = 0)
            is a cell boundary a few empty rows up; the row just below it is filled where
            the object stands (:func:`surface` flattens it onto the table).
    """

    width: np.ndarray
    cell_m: float
    corner_m: np.ndarray


def close_model(
    points: np.ndarray, cell_m: float = CELL_M, view: View | None = None
) -> trimesh.Trimesh:
    """The watertight, outward-oriented surface of a completed model in its object frame
    (:func:`half_widths`, then :func:`surface`)."""
    return surface(half_widths(points, cell_m, view))


@dataclass(frozen=True)
class View:
    """What the camera saw of the model, object frame (metres).

    Attributes:
        viewpoint_m: ``(3,)`` the camera's optical centre.
        seen: ``(M, 3)`` the points it saw (the completed model's unmirrored half).
    """

    viewpoint_m: np.ndarray
    seen: np.ndarray


def half_widths(points: np.ndarray, cell_m: float = CELL_M, view: View | None = None) -> HalfWidths:
    """The solid a completed model bounds, as half-widths about its plane.

    Args:
        points: ``(N, 3)`` the completed model in the object frame (metres): symmetric
            about x = 0, standing on the table z = 0.
        cell_m: the cells' edge (grown when the object would need more than
            :data:`MAX_CELLS` cells in 3-D).
        view: the camera's view; with it, columns the object itself hid from the camera
            below their lowest point are carried down to the table too
            (:func:`_hidden_below`).

    Raises:
        ValueError: fewer than 4 finite points above the table.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1) & (points[:, 2] > 0.0)]
    if len(points) < 4:
        raise ValueError("a surface needs at least 4 finite points above the table")
    reach = np.abs(points[:, 0]).max()
    lower = np.array([-reach, points[:, 1].min(), 0.0])
    upper = np.array([reach, points[:, 1].max(), points[:, 2].max()])
    cell = max(cell_m, float(np.prod(upper - lower + 2 * cell_m) / MAX_CELLS) ** (1.0 / 3.0))
    # The first point along y at the centre of its cell: the surface passes through the
    # centres of the outermost cells.
    lower[1] -= 0.5 * cell
    rows = np.floor((points[:, 1:] - lower[1:]) / cell).astype(int) + MARGIN_CELLS
    shape = tuple(rows.max(axis=0) + MARGIN_CELLS + 1)
    width = _fill_gaps(_half_widths(rows, np.abs(points[:, 0]), shape, cell))
    corner = np.array([lower[1], 0.0]) - MARGIN_CELLS * cell
    # One row below the table: the surface, half a cell inside, then lies below it and is
    # flattened onto it.
    width = _extend_base(width, MARGIN_CELLS - 1, int(np.ceil(BASE_BAND_M / cell)))
    if view is not None:
        # Lines of sight through gaps between the seen points stop single columns: close
        # those slits too.
        width = _fill_gaps(_hidden_below(width, cell, corner, view, MARGIN_CELLS))
    return HalfWidths(width, cell, corner)


def surface(solid: HalfWidths) -> trimesh.Trimesh:
    """The solid's surface, outward-oriented, its base flattened onto the table.

    The solid is the intersection of two regions with signed distances (in cells, positive
    inside): the walls ``|x| <= w(y, z)``, at ``w - |x|``, and the outline of the map's
    filled cells extruded along x, at the (y, z) distance to the centres of its outermost
    cells (where their points lie on average). Both are smoothed over (y, z) by a Gaussian
    of :data:`BLUR_CELLS`; marching cubes cuts the smaller of the two at zero, so the walls
    lie on the points and the edges between a wall and the outline stay sharp.
    """
    from skimage.measure import marching_cubes

    cell, width = solid.cell_m, solid.width
    filled = width > 0.0
    outline = np.where(
        filled,
        ndimage.distance_transform_edt(filled) - 1.0,
        -ndimage.distance_transform_edt(~filled),
    )
    outline = ndimage.gaussian_filter(outline, BLUR_CELLS)
    # The half-widths smoothed over the filled cells, and carried past the outline so the
    # walls meet it without a step.
    weight = ndimage.gaussian_filter(filled.astype(float), BLUR_CELLS)
    smooth = ndimage.gaussian_filter(width, BLUR_CELLS) / np.maximum(weight, 1e-12)
    nearest = ndimage.distance_transform_edt(~filled, return_distances=False, return_indices=True)
    smooth = smooth[nearest[0], nearest[1]]
    half = int(np.ceil(width.max() / cell)) + 2
    centres_x = (np.arange(2 * half) - half + 0.5) * cell
    walls = (smooth[None, :, :] - np.abs(centres_x)[:, None, None]) / cell
    field = np.minimum(walls, outline[None, :, :]).astype(np.float32)
    # Values at the level make marching cubes put vertices of several edges on one grid
    # node; kept NEAR_LEVEL away from it, no two vertices come within a micrometre, and
    # the file's rounding merges none (the surface moves by less than 0.01 mm).
    field[np.abs(field) < NEAR_LEVEL] = -NEAR_LEVEL
    if not field.max() > 0.0:
        raise ValueError(
            "the model encloses no solid: its points lie in layers thinner than a cell"
        )
    vertices, faces, _, _ = marching_cubes(field, 0.0)
    origin = np.array([-half * cell, *solid.corner_m]) + 0.5 * cell
    vertices = origin + cell * vertices
    # The filled row below the table puts the surface under it: flatten that onto it.
    vertices[:, 2] = np.maximum(vertices[:, 2], 0.0)
    return _welded(vertices, faces)


def _welded(vertices: np.ndarray, faces: np.ndarray) -> trimesh.Trimesh:
    """The mesh with its vertices rounded to the micrometre an OBJ file keeps, any that then
    coincide merged and triangles that lose a corner to that dropped (the file reads back
    as the same mesh); outward-oriented."""
    steps = np.round(vertices * 10.0**OBJ_DECIMALS).astype(np.int64)
    # One integer per vertex (21 bits a coordinate: +-1 m in micrometres) sorts 5x faster
    # than rows.
    low = steps.min(axis=0)
    keys = ((steps[:, 0] - low[0]) << 42) | ((steps[:, 1] - low[1]) << 21) | (steps[:, 2] - low[2])
    _, first, index = np.unique(keys, return_index=True, return_inverse=True)
    faces = index.reshape(-1)[faces]
    kept = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    mesh = trimesh.Trimesh(steps[first] / 10.0**OBJ_DECIMALS, faces[kept], process=False)
    mesh.remove_unreferenced_vertices()
    if signed_volume(mesh) < 0.0:
        mesh.invert()
    return mesh


def _half_widths(
    rows: np.ndarray, reach: np.ndarray, shape: tuple[int, int], cell_m: float
) -> np.ndarray:
    """Per cell of the (y, z) map, of its points with at least half the cell's largest
    reach, the median reach, or where their interquartile range exceeds ``cell_m`` the
    95th percentile; 0 where no point falls, or so few that they are the noise scattered
    past the object's outline (:data:`SPARSE_SHARE`)."""
    cells = np.ravel_multi_index((rows[:, 0], rows[:, 1]), shape)
    counts = np.bincount(cells, minlength=int(np.prod(shape)))
    dense = counts >= SPARSE_SHARE * np.median(counts[counts > 0])
    cells, reach = cells[dense[cells]], reach[dense[cells]]
    largest = np.zeros(int(np.prod(shape)))
    np.maximum.at(largest, cells, reach)
    outer = reach >= 0.5 * largest[cells]
    cells, reach = cells[outer], reach[outer]
    order = np.lexsort((reach, cells))
    cells, reach = cells[order], reach[order]
    starts = np.flatnonzero(np.r_[True, cells[1:] != cells[:-1]])
    counts = np.diff(np.r_[starts, len(cells)])

    def quantile(q: float) -> np.ndarray:
        return reach[starts + np.floor(q * (counts - 1)).astype(int)]

    # A wall's points lie within the noise of one reach; a face crossing the cell (a top
    # seen from above) spreads them from the plane to its edge, whose reach is their top.
    crossing = quantile(0.75) - quantile(0.25) > cell_m
    width = np.zeros(int(np.prod(shape)))
    width[cells[starts]] = np.where(crossing, quantile(0.95), quantile(0.5))
    return width.reshape(shape)


def _fill_gaps(width: np.ndarray) -> np.ndarray:
    """Close gaps of up to :data:`GAP_CELLS` in the half-width map, keep its largest piece
    (stray points make specks) and give the cells it gained the width of the nearest cell
    that had one."""
    seen = width > 0.0
    square = np.ones((GAP_CELLS, GAP_CELLS), dtype=bool)
    mask = ndimage.binary_closing(seen, structure=square) | seen
    labels, count = ndimage.label(mask)
    if count > 1:
        sizes = np.bincount(labels.ravel())
        sizes[0] = 0
        mask = labels == int(np.argmax(sizes))
    mask = ndimage.binary_fill_holes(mask)
    nearest = ndimage.distance_transform_edt(~seen, return_distances=False, return_indices=True)
    return np.where(mask, width[nearest[0], nearest[1]], 0.0)


def _hidden_below(
    width: np.ndarray, cell: float, corner: np.ndarray, view: View, table_row: int
) -> np.ndarray:
    """Carry each column left hanging by :func:`_extend_base` down from its lowest filled
    cell, with that cell's width, as far as the camera could not have seen the solid there:
    where the seen points lie nearer to the camera along the same line of sight (by more
    than two cells). A view along the plane sees the top face and the near end and none of
    the side walls, so the region under the top is hidden, not empty; under a drill's body
    the camera sees through to what lies behind, and the column stays open."""
    camera = np.asarray(view.viewpoint_m, dtype=float)
    seen = np.asarray(view.seen, dtype=float) - camera
    if len(seen) == 0:
        return width
    distance = np.linalg.norm(seen, axis=1)
    axis = seen.mean(axis=0) / np.linalg.norm(seen.mean(axis=0))
    # Lines of sight binned by angle: a cell's width at the object's distance.
    step = cell / float(np.median(distance))
    bins = _angles(seen, axis) / step
    origin = np.floor(bins.min(axis=0)).astype(int) - 1
    shape = np.floor(bins.max(axis=0)).astype(int) - origin + 2
    nearest = np.full(shape, np.inf)
    index = np.floor(bins).astype(int) - origin
    np.minimum.at(nearest, (index[:, 0], index[:, 1]), distance)
    # Every line of sight is also blocked by the points of its neighbouring bins.
    nearest = ndimage.minimum_filter(nearest, size=3, mode="nearest")
    filled = width > 0.0
    occupied = filled.any(axis=1)
    lowest = np.where(occupied, np.argmax(filled, axis=1), 0)
    rows, columns = np.nonzero(
        (np.arange(width.shape[1])[None, :] < lowest[:, None])
        & (np.arange(width.shape[1])[None, :] >= table_row)
        & occupied[:, None]
    )
    if len(rows) == 0:
        return width
    w = width[rows, lowest[rows]]
    # The solid there would show the camera its near wall.
    near_x = np.sign(camera[0]) * w
    candidates = np.column_stack(
        [near_x, corner[0] + (rows + 0.5) * cell, corner[1] + (columns + 0.5) * cell]
    )
    sight = candidates - camera
    at = np.floor(_angles(sight, axis) / step).astype(int) - origin
    inside = np.all((at >= 0) & (at < shape), axis=1) & (sight @ axis > 0.0)
    blocked = np.zeros(len(rows), dtype=bool)
    blocked[inside] = nearest[at[inside, 0], at[inside, 1]] < (
        np.linalg.norm(sight[inside], axis=1) - 2.0 * cell
    )
    hidden = np.zeros(width.shape, dtype=bool)
    hidden[rows, columns] = blocked
    # From the lowest filled cell down, as long as every cell on the way is hidden.
    below = np.zeros(width.shape, dtype=bool)
    run = np.ones(width.shape[0], dtype=bool)
    for row in range(width.shape[1] - 1, table_row - 1, -1):
        active = occupied & (row < lowest)
        run &= ~active | hidden[:, row]
        below[:, row] = active & run
    # A column carried down to the table takes the row below it too, as the base does.
    below[:, table_row - 1] = below[:, table_row]
    extended = width.copy()
    extended[below] = np.broadcast_to(
        width[np.arange(width.shape[0]), lowest][:, None], width.shape
    )[below]
    return extended


def _angles(directions: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """``(N, 2)`` where directions meet the plane one unit along ``axis`` (a unit vector),
    in two axes of that plane: about their angles from ``axis`` (rad) near it."""
    side = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(side, axis)
    depth = directions @ axis
    return np.column_stack([directions @ side, directions @ up]) / depth[:, None]


def _extend_base(width: np.ndarray, table_row: int, band_cells: int) -> np.ndarray:
    """Extend every row (y) whose lowest filled cell is within ``band_cells`` of the lowest
    of all down to ``table_row`` with the width it has there."""
    occupied = (width > 0.0).any(axis=1)
    lowest = np.where(occupied, np.argmax(width > 0.0, axis=1), width.shape[1])
    standing = np.flatnonzero(occupied & (lowest <= lowest[occupied].min() + band_cells))
    extended = width.copy()
    for row in standing:
        extended[row, table_row : lowest[row]] = width[row, lowest[row]]
    return extended
