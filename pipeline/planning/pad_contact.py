"""Predicted pad contact: a vertical pad's taxel grid (:class:`PadTaxels`; flat, or an
SDH-2 distal pad with its curved tip) moving horizontally toward a sampled surface, where
it first touches, how much of it then touches and how inclined the surface is there
(:func:`pad_coverage`). Grasp candidates score their contacts with it
(:mod:`pipeline.planning.candidate`), and :mod:`pipeline.planning.next_grasp` predicts the
contacts a next grasp would add.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from pipeline.geometry.pad_layout import pad_grid
from pipeline.planning import sdh_geometry as sdh
from pipeline.planning.order_statistics import lexsort_pair
from pipeline.types import PadLayout


@dataclass(frozen=True)
class PadContact:
    """Where a pad moving toward the surface stops and how much of it touches.

    Attributes:
        touch_m: position of the pad's flat surface along its motion when it stops (m).
        coverage: fraction of its taxels within the tolerance of the surface then.
        points: ``(K, 3)`` surface points under those taxels.
        surface_fit: what the surface's slopes are fitted to (:class:`SurfaceCells`),
            fitted when first asked for: a candidate rejected before its score needs none.
            None: a surface facing the pad.
    """

    touch_m: float
    coverage: float
    points: np.ndarray
    surface_fit: SurfaceCells | None = field(default=None, repr=False, compare=False)

    @functools.cached_property
    def _slopes(self) -> tuple[float, float]:
        return self.surface_fit.slopes() if self.surface_fit is not None else (0.0, 0.0)

    @property
    def inclination_rad(self) -> float:
        """Angle between the surface's normal at the touch and the pad's."""
        return float(np.arctan(np.hypot(*self._slopes)))

    @property
    def turn_rad(self) -> float:
        """The part of the inclination about the vertical, signed: the angle about +z by
        which the side in front of the pad is turned from facing it (from the surface's
        slope across the pad)."""
        return float(-np.arctan(self._slopes[0]))

    @property
    def quality(self) -> float:
        """Coverage times ``cos^2`` of the inclination: an inclined surface takes the pad's
        force partly along itself, and the pad slides off it."""
        return self.coverage * math.cos(self.inclination_rad) ** 2

    def stops_before(self, point_m: np.ndarray, direction: np.ndarray) -> bool:
        """Whether the pad, moving along ``direction`` (the unit it was predicted with),
        stops before reaching ``point_m`` (frame R): past the object's centre, the surface
        it found is the far side, met from inside a hole in the model."""
        return self.touch_m < float(np.asarray(point_m) @ np.asarray(direction))


@dataclass(frozen=True)
class SurfaceCells:
    """The cells one pad of a :func:`pad_coverages` call sees, as that call found them
    for every pad (the arrays are shared by its contacts, ``cells`` picks this pad's):
    each seen cell's taxel index within its pad (``local``), the surface in front of it
    and whether it senses (``fits``); the touch and the tolerance (m). Kept as found, the
    taxels' offsets and heights are picked only for a contact whose slopes are asked
    for."""

    taxels: PadTaxels
    local: np.ndarray
    surface: np.ndarray
    fits: np.ndarray
    cells: slice
    touch_m: float
    tolerance_m: float

    def slopes(self) -> tuple[float, float]:
        """:func:`_slopes` over the pad's sensing cells (its bare cells left out)."""
        fits = self.fits[self.cells]
        local = self.local[self.cells][fits]
        cols = len(self.taxels.col_u)
        return _slopes(
            self.taxels.col_u[local % cols],
            self.taxels.row_z[local // cols],
            self.surface[self.cells][fits],
            self.touch_m,
            self.tolerance_m,
        )


#: Fewest taxel rows a pad must touch for its contact to be a side of the object.
MIN_CONTACT_ROWS = 3
#: Depth of the surface layer a pad meets in each taxel cell (m): over twice the cloud's
#: depth noise, thinner than any graspable object's wall-to-wall depth.
LAYER_M = 0.006


@dataclass(frozen=True)
class PadTaxels:
    """A vertical pad's taxel grid as it moves horizontally (metres): ``col_u`` the
    columns' offsets across the motion (evenly ``pitch_m`` apart), ``row_z`` the rows'
    heights, ``row_recess`` how far each row lies behind the pad's flat surface (a tip
    curving away from the object). ``senses`` ``(rows, columns)`` marks the cells that are
    taxels (None: all); the others are bare parts of the finger (a pad's edges, the finger
    below and beside it): they stop the pad where they meet the surface first, but never
    count as touching."""

    col_u: np.ndarray
    row_z: np.ndarray
    row_recess: np.ndarray
    pitch_m: float
    senses: np.ndarray | None = None

    @property
    def z_range_m(self) -> tuple[float, float]:
        """The heights the taxels see: from half a pitch below the lowest row to half a
        pitch above the highest. Only points in this range can touch the pad."""
        half = self.pitch_m / 2.0
        return float(self.row_z.min()) - half, float(self.row_z.max()) + half


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
    return curved_pad_taxels(
        pad, centre_z_m, sdh.DISTAL_PAD_CURVED_ROWS, sdh.DISTAL_PAD_CURVE_RADIUS_M
    )


def curved_pad_taxels(
    pad: PadLayout, centre_z_m: float, curved_rows: int, radius_m: float
) -> PadTaxels:
    """A pad on a vertical link whose ``curved_rows`` rows nearest the tip (down) lie on a
    cylinder of ``radius_m`` curving away, recessed behind the flat surface."""
    positions, _ = pad_grid(pad.rows, pad.cols, pad.pitch_m, curved_rows, radius_m)
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
    pitch of it across and in height, and of those the layer :data:`LAYER_M` deep behind
    the nearest (a z-buffer seen from the pad: a completed cloud also holds the far side,
    which is not the surface in front of it); their median position along
    ``direction`` is the surface in front of it. The pad stops when its first taxel
    reaches the surface (a bare cell's, :attr:`PadTaxels.senses`, included); the
    sensing taxels whose surface is then within ``tolerance_m`` count as touching.

    Returns:
        The contact, or None when no point lies in front of any taxel or the touching
        taxels span fewer than three rows (about 10 mm: the pad meets an edge or a
        horizontal top, not a side, or a bare part of the finger meets the object first).
    """
    origin_m = np.asarray(origin_m, dtype=np.float64)
    direction = np.asarray(direction, dtype=np.float64)
    return pad_coverages(points_robot, origin_m[None], direction[None], taxels, tolerance_m)[0]


def pad_coverages(
    points_robot: np.ndarray,
    origins_m: np.ndarray,
    directions: np.ndarray,
    taxels: PadTaxels,
    tolerance_m: float,
) -> list[PadContact | None]:
    """:func:`pad_coverage` of the same pad moving from each of ``origins_m`` along each of
    ``directions`` (both ``(Q, 3)``) at once: one pass over the points for all the pads of
    a hand (the points' order within each pad is the cloud's, as one at a time)."""
    half = taxels.pitch_m / 2.0
    z_low, z_high = taxels.z_range_m
    laterals = np.column_stack([-directions[:, 1], directions[:, 0]])
    z = points_robot[:, 2]
    # Offsets across each pad's motion, (Q, N): the height tests first, on the points alone.
    at_rows = np.flatnonzero((z >= z_low) & (z <= z_high))
    # Every point's nearest row, and whether it lies within half a pitch of it (between
    # curved rows it may not): the same for every pad, so found once per point.
    z = z[at_rows]
    order = np.argsort(taxels.row_z)
    sorted_z = taxels.row_z[order]
    point_row = order[np.searchsorted((sorted_z[1:] + sorted_z[:-1]) / 2.0, z)]
    point_inside = np.abs(z - taxels.row_z[point_row]) <= half
    at_rows, point_row = at_rows.compress(point_inside), point_row.compress(point_inside)
    starts = np.sum(origins_m[:, :2] * laterals, axis=1)
    # Selections by ``take`` (of rows: ``axis=0``): the same elements as an index array's,
    # several times faster for rows of a 2-D array.
    u = laterals @ points_robot[:, :2].take(at_rows, axis=0).T - starts[:, None]
    # ``np.nonzero`` of the (Q, N) mask, row by row, from its flat indices.
    flat = np.flatnonzero((u >= taxels.col_u.min() - half) & (u <= taxels.col_u.max() + half))
    query, index = np.divmod(flat, u.shape[1])
    if len(query) == 0:
        return [None] * len(origins_m)
    u = u.take(flat)
    source = at_rows.take(index)
    cols = len(taxels.col_u)
    per_pad = len(taxels.row_z) * cols
    col = np.clip(np.round((u - taxels.col_u[0]) / taxels.pitch_m).astype(int), 0, cols - 1)
    kept = points_robot.take(source, axis=0)
    # Each pad's taxels numbered apart: taxel // per_pad is the pad.
    taxel = query * per_pad + (point_row.take(index) * cols + col)
    # Depths along each pad's motion as one pad alone computes them (the same rounding:
    # the offsets from the pads' origins element by element, one product per pad).
    bounds = np.searchsorted(query, np.arange(len(origins_m) + 1)).tolist()
    offsets = kept - origins_m.take(query, axis=0)
    depth = np.concatenate(
        [
            offsets[start:end] @ direction
            for direction, start, end in zip(directions, bounds[:-1], bounds[1:], strict=True)
        ]
    )
    # Each taxel's layer, before sorting: the sort then orders that layer alone.
    nearest = np.full(len(origins_m) * per_pad, np.inf)
    np.minimum.at(nearest, taxel, depth)
    layer = depth <= nearest.take(taxel) + LAYER_M
    taxel, depth, source = taxel.compress(layer), depth.compress(layer), source.compress(layer)
    # By taxel, and by depth within one.
    by_taxel = lexsort_pair(depth, taxel, len(nearest))
    # The points' indices follow the sort; the points themselves are taken for the
    # contacts alone.
    taxel, depth, source = taxel.take(by_taxel), depth.take(by_taxel), source.take(by_taxel)
    first, counts = _runs(taxel)  # every taxel keeps its nearest point
    seen = taxel[first]
    local = seen % per_pad
    surface = depth[first + counts // 2] + taxels.row_recess[local // cols]
    # Every pad's first touch at once: the nearest surface seen by at least two points (a
    # single point may be a mixed pixel at the silhouette), else the nearest.
    pad_first, pad_cells = _runs(seen // per_pad)
    pads = seen[pad_first] // per_pad
    touch_supported = np.minimum.reduceat(np.where(counts >= 2, surface, np.inf), pad_first)
    touch = np.where(
        np.isfinite(touch_supported), touch_supported, np.minimum.reduceat(surface, pad_first)
    )
    of_cell = np.repeat(np.arange(len(pads)), pad_cells)
    rows = local // cols
    touches = surface <= touch[of_cell] + tolerance_m
    senses = taxels.senses
    fits = np.ones(len(rows), dtype=bool) if senses is None else senses.ravel()[local]
    touches &= fits
    touched_rows = np.zeros((len(pads), len(taxels.row_z)), dtype=bool)
    touched_rows[of_cell[touches], rows[touches]] = True
    row_counts = np.count_nonzero(touched_rows, axis=1)
    touching = np.add.reduceat(touches, pad_first)
    sensing = per_pad if senses is None else int(np.count_nonzero(senses))
    # The points of the touching taxels, every pad's gathered at once: each pad's run
    # follows the one before, so a contact's points are a slice of them.
    under_touching = np.repeat(touches, counts)
    touched = points_robot.take(source.compress(under_touching), axis=0)
    touched_ends = np.cumsum(np.add.reduceat(np.where(touches, counts, 0), pad_first)).tolist()
    contacts: list[PadContact | None] = [None] * len(origins_m)
    # Python numbers for the loop: an array's elements one at a time cost more.
    firsts, cell_counts, pad_of = pad_first.tolist(), pad_cells.tolist(), pads.tolist()
    touch_of, touching_of = touch.tolist(), touching.tolist()
    for k in np.flatnonzero(row_counts >= MIN_CONTACT_ROWS).tolist():  # else an edge or a top
        pad = pad_of[k]
        start = touched_ends[k - 1] if k else 0
        contacts[pad] = PadContact(
            touch_m=touch_of[k] + float(origins_m[pad] @ directions[pad]),
            coverage=touching_of[k] / sensing,
            points=touched[start : touched_ends[k]],
            # The surface's slopes from the taxels' cells alone, as without bare cells.
            surface_fit=SurfaceCells(
                taxels,
                local,
                surface,
                fits,
                slice(firsts[k], firsts[k] + cell_counts[k]),
                touch_of[k],
                tolerance_m,
            ),
        )
    return contacts


def _runs(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each run of equal values of the sorted, non-empty ``ids`` starts, and its
    length (``np.unique``'s first indices and counts, without its sort)."""
    changes = np.empty(len(ids), dtype=bool)
    changes[0] = True
    np.not_equal(ids[1:], ids[:-1], out=changes[1:])
    starts = np.flatnonzero(changes)
    lengths = np.empty_like(starts)
    lengths[:-1] = starts[1:] - starts[:-1]
    lengths[-1] = len(ids) - starts[-1]
    return starts, lengths


def _slopes(
    u: np.ndarray, z: np.ndarray, surface: np.ndarray, touch: float, tolerance_m: float
) -> tuple[float, float]:
    """The surface's slopes ``b`` across the pad and ``c`` in height, from a plane
    ``surface = a + b u + c z`` fitted over the taxels whose surface lies within three
    tolerances of the touch (too few of them, or a degenerate layout: both 0); the angle
    between the pad's normal and the surface's is ``arctan(hypot(b, c))``."""
    near = surface <= touch + 3.0 * tolerance_m
    count = np.count_nonzero(near)
    if count < 4:
        return 0.0, 0.0
    design = np.empty((count, 3))
    design[:, 0] = 1.0
    design[:, 1] = u[near]
    design[:, 2] = z[near]
    # lstsq's rank has matrix_rank's threshold (largest singular value x eps x rows).
    (_, b, c), _, rank, _ = np.linalg.lstsq(design, surface[near], rcond=None)
    return (float(b), float(c)) if rank == 3 else (0.0, 0.0)
