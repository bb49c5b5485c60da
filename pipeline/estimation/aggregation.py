"""Gated Gaussian sums over a voxel-aggregated cloud, for gates much wider than a voxel.

Stage 1 needs, per taxel, only the weight mass ``a = sum_n w(p_n)`` and the weighted sum
``sum_n w(p_n) p_n`` with ``w = N(p; t, C)`` gated at ``D2 < 7.815`` (docs/method.md §2).
Before the first update the gates are tens of millimetres wide and cover most of the cloud,
so exact sums cost ``O(M N)`` per iteration. Here the points are binned once into an
axis-aligned voxel grid and every voxel keeps its count ``n``, centroid ``c`` and scatter
``S = sum (p - c)(p - c)^T``. With ``u = c - t``, ``A = C^-1`` and ``a = A u`` the
second-order expansion of the Gaussian about the centroid gives, per voxel,

    sum w(p)   ~ w(c) (n + (a^T S a - tr(A S)) / 2)
    sum w(p) p ~ c sum w(p) - w(c) S a

(the first-order term vanishes because ``c`` is the centroid); a voxel is inside the gate
when its centroid is. The voxel edges ``h`` are chosen from the gates so that
``||H A H|| <= ratio^2`` for every gate (``H = diag(h)``): a voxel is then at most
``ratio * sqrt(3) / 2`` wide in whitened units, the neglected terms are third order in
``ratio``, and the only other error is from voxels straddling the gate boundary, where the
density is ``exp(-7.815 / 2) = 2 %`` of its peak. With ``ratio = 0.5`` the masses and weighted
means agree with the exact sums to well under 1 % of the mass / a fraction of a millimetre
(``tests/test_estimation_aggregation.py``), while a 20,000-point cloud shrinks to a few
thousand voxels. The cost per call grows with the number of (taxel, voxel) pairs near each
gate (a KD-tree query over the voxel centroids), independent of ``N`` once the grid is built
(``O(N log N)``, once per voxel size).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from pipeline.estimation.indexsets import DENSE_RANGE_FACTOR, ranks, unique_inverse

#: chi-square quantile, 3 degrees of freedom, 95 % (paper eq. 9).
GATE_CHI2_3DOF_95 = 7.815
#: Largest voxel extent in whitened gate units (see the module docstring).
VOXEL_RATIO = 0.5
#: The entries of a lower-triangular 3 x 3 matrix and the off-diagonal ones of a symmetric one.
_LOWER = ((0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2))
_OFF = ((0, 1), (0, 2), (1, 2))
#: Rounds of per-axis growth of the voxel edges (:func:`voxel_exponents`); the second
#: takes what the first left, further rounds change the edges by well under a quarter octave.
_AXIS_ROUNDS = 2
#: Relative margin that keeps ``C - D`` positive definite against rounding.
_INSIDE = 1e-6


@dataclass(frozen=True)
class VoxelMoments:
    """Per-voxel moments of a cloud.

    Attributes:
        count: ``(V,)`` points per voxel.
        centroid: ``(V, 3)`` mean position of each voxel's points (m).
        scatter: ``(V, 3, 3)`` ``sum (p - c)(p - c)^T`` over each voxel's points (m^2).
        voxel_of_point: ``(N,)`` voxel index of every point.
        size_m: ``(3,)`` voxel edge lengths along x, y, z (m).
        label: ``(V,)`` label shared by each voxel's points (all 0 without labels).
    """

    count: np.ndarray
    centroid: np.ndarray
    scatter: np.ndarray
    voxel_of_point: np.ndarray
    size_m: np.ndarray
    label: np.ndarray
    _trees: dict = field(default_factory=dict, repr=False, compare=False)

    def tree(self, units_m: np.ndarray | None = None) -> cKDTree:
        """KD-tree over the centroids in voxel units (``centroid / size_m``), or in the axes'
        ``units_m`` (3,) (m), built once per units."""
        units = self.size_m if units_m is None else units_m
        key = tuple(float(u) for u in units)
        if key not in self._trees:
            self._trees[key] = cKDTree(
                self.centroid / units, balanced_tree=False, compact_nodes=False
            )
        return self._trees[key]


def voxel_moments(
    points_m: np.ndarray,
    size_m: np.ndarray,
    labels: np.ndarray | None = None,
    coordinates: np.ndarray | None = None,
    label_ranks: tuple[np.ndarray, np.ndarray] | None = None,
) -> VoxelMoments:
    """Bin ``points_m`` (N, 3) into voxels of edges ``size_m`` (grid anchored at the origin);
    with ``labels`` ((N,) small non-negative or -1 ints) points of different labels never
    share a voxel.

    A caller binning the same points on several grids may pass what every grid needs:
    ``coordinates``, the points as a contiguous ``(3, N)`` array, and ``label_ranks``, the
    distinct labels and each point's index among them (``np.unique(labels,
    return_inverse=True)``); at a million points they cost half as much as a grid.
    """
    # Column by column (one contiguous copy): numpy reduces, divides and gathers an (N, 3)
    # array along its first axis several times slower.
    if coordinates is None:
        coordinates = np.ascontiguousarray(np.asarray(points_m, dtype=float).T)
    columns = [np.floor(coordinates[k] / size_m[k]).astype(np.int64) for k in range(3)]
    extent = []
    for column in columns:
        column -= column.min()
        extent.append(int(column.max(initial=0)) + 1)
    # The cells' keys in C order (np.ravel_multi_index's, without its checks).
    keys = columns[0] * (extent[1] * extent[2])
    keys += columns[1] * extent[2]
    keys += columns[2]
    label = None
    if labels is not None:
        # Split each cell by label: (cell, label) pairs, ordered by cell, then label. Keyed
        # directly when the range of cells x labels is small enough to count, else by the
        # ranks of the occupied cells (a range of cells present x labels, not of the grid).
        values, label_rank = ranks(labels) if label_ranks is None else label_ranks
        if extent[0] * extent[1] * extent[2] * len(values) > DENSE_RANGE_FACTOR * len(keys):
            _, keys, _ = unique_inverse(keys)
        pairs, voxel_of_point, count = unique_inverse(keys * len(values) + label_rank)
        label = values[pairs % len(values)]
    else:
        _, voxel_of_point, count = unique_inverse(keys)
    voxels = len(count)
    if label is None:
        label = np.zeros(voxels, dtype=np.int64)
    # Centroids and scatters stored column by column ((V, 3) and (V, 3, 3) views of
    # (3, V) and (3, 3, V) arrays): the Gaussian sums gather them one entry at a time.
    centroid = np.stack(
        [np.bincount(voxel_of_point, weights=column, minlength=voxels) for column in coordinates]
    )
    centroid /= count
    centroid = centroid.T
    offsets = [coordinates[k] - centroid[:, k].take(voxel_of_point) for k in range(3)]
    scatter = np.empty((3, 3, voxels)).transpose(2, 0, 1)
    for i in range(3):
        for j in range(i, 3):
            column = np.bincount(voxel_of_point, weights=offsets[i] * offsets[j], minlength=voxels)
            scatter[:, i, j] = scatter[:, j, i] = column
    return VoxelMoments(count.astype(float), centroid, scatter, voxel_of_point, size_m, label)


def voxel_exponents(covariances: np.ndarray, ratio: float = VOXEL_RATIO) -> np.ndarray:
    """Exponents ``e`` of voxel edges ``h = 2^(e / 4)`` (m) with ``||H C^-1 H|| <= ratio^2``
    for every covariance in ``covariances`` (T, 3, 3), rounded down to quarter octaves so
    that nearby gates share one grid.

    The bound is ``H^2 <= ratio^2 C`` (Loewner order) for every gate. The edges start from
    the axes' smallest stds scaled by one common factor until some gate is met, then each
    axis in turn grows as far as every gate allows: a gate long and thin across a
    horizontal diagonal (the back's gates under a broad plane prior) limits the horizontal
    edges but not the vertical one, which a common factor alone would shrink with them.
    """
    scale = np.sqrt(np.min(np.diagonal(covariances, axis1=1, axis2=2), axis=0))
    normalised = covariances / np.outer(scale, scale)[None]
    smallest = float(np.min(np.linalg.eigvalsh(normalised)[:, 0]))
    # Just inside every gate, so that C - D stays invertible.
    variances = (1.0 - _INSIDE) * smallest * scale**2
    for _ in range(_AXIS_ROUNDS):
        for k in range(3):
            # The largest d with S - d e_k e_k^T >= 0 (S = C - D) is the Schur complement
            # of the other two axes' block R in S: S_kk - b^T R^-1 b, with b = S[rest, k].
            slack = covariances - np.diag(variances)[None]
            i, j = (axis for axis in range(3) if axis != k)
            minor = slack[:, i, i] * slack[:, j, j] - slack[:, i, j] ** 2
            b_i, b_j = slack[:, i, k], slack[:, j, k]
            coupled = (
                b_i**2 * slack[:, j, j] - 2.0 * b_i * b_j * slack[:, i, j] + b_j**2 * slack[:, i, i]
            )
            # Where rounding leaves the other block no minor, axis k keeps its room only
            # when it is uncoupled from that block.
            safe = np.where(minor > 0.0, minor, 1.0)
            room = np.where(
                minor > 0.0,
                slack[:, k, k] - coupled / safe,
                np.where(coupled > 0.0, 0.0, slack[:, k, k]),
            )
            variances[k] += (1.0 - _INSIDE) * max(float(np.min(room)), 0.0)
    edges_m = ratio * np.sqrt(variances)
    return np.floor(4.0 * np.log2(edges_m)).astype(np.int64)


def _candidate_pairs(
    moments: VoxelMoments, centres: np.ndarray, covariances: np.ndarray
) -> np.ndarray:
    """(centre, voxel) pairs whose centroid may lie inside the centre's gate: a superset of
    the gates' voxels, from one tree-to-tree query over the centroids.

    The query is a ball in voxel units (where the gates are about equally wide along every
    axis) whose radius is the longest semi-axis of any gate there, or, when it is smaller,
    a box that holds every gate's bounding box (a Chebyshev ball in units of the box's
    half-widths rounded up to quarter octaves, so that the next iterations' gates reuse
    its tree): for gates long and thin across a diagonal, the ball's radius is the long
    axis along every axis while the box keeps each axis's own extent.
    """
    in_voxel_units = covariances / np.outer(moments.size_m, moments.size_m)[None]
    longest = np.max(np.linalg.eigvalsh(in_voxel_units)[:, -1], initial=0.0)
    radius = float(np.sqrt(GATE_CHI2_3DOF_95 * longest))
    ball_volume = 4.0 / 3.0 * np.pi * radius**3 * float(np.prod(moments.size_m))
    half_m = np.sqrt(GATE_CHI2_3DOF_95 * np.max(np.diagonal(covariances, axis1=1, axis2=2), axis=0))
    box_m = np.exp2(np.ceil(4.0 * np.log2(half_m)) / 4.0)
    if np.prod(2.0 * box_m) < ball_volume:
        return cKDTree(centres / box_m).sparse_distance_matrix(
            moments.tree(box_m), 1.0, p=np.inf, output_type="ndarray"
        )
    return cKDTree(centres / moments.size_m).sparse_distance_matrix(
        moments.tree(), radius, output_type="ndarray"
    )


def gaussian_sums(
    moments: VoxelMoments,
    centres: np.ndarray,
    covariances: np.ndarray,
    normaliser: np.ndarray,
    allowed: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gated mass and weighted sum of every centre over the aggregated cloud.

    Candidate voxels come from one tree-to-tree query (:func:`_candidate_pairs`); every
    candidate is then tested exactly on its centroid.

    Each pair's arithmetic is written out on the six distinct entries of the centre's
    ``L^-1`` (``C = L L^T``) and of the voxel's scatter, gathered one column at a time from
    their small per-centre / per-voxel arrays: with hundreds of thousands of candidate pairs
    under the wide gates of a hard start, gathering whole ``3 x 3`` matrices per pair and
    contracting them with ``einsum`` cost several times the arithmetic itself.

    Args:
        moments: the voxel moments of the points.
        centres: ``(T, 3)`` Gaussian centres, same frame as the points.
        covariances: ``(T, 3, 3)`` Gaussian covariances (m^2).
        normaliser: ``(T,)`` density normalisers ``1 / sqrt((2 pi)^3 det C)``.
        allowed: optional ``allowed(centre_indices, voxel_indices)`` -> bool array, False
            where a centre must ignore a voxel.

    Returns:
        ``(T,)`` masses, ``(T, 3)`` weighted sums ``sum w p`` and a ``(V,)`` bool mask of the
        voxels inside some gate.
    """
    count = len(centres)
    pairs = _candidate_pairs(moments, centres, covariances)
    taxel, voxel = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    # Whitened offsets y = L^-1 (c - t): D2 = |y|^2 and C^-1 (c - t) = L^-T y. The centres'
    # entries as contiguous (T,) arrays (gathered pair by pair); the pairs inside the gates
    # (and the filter) kept by their indices (a boolean mask per array costs several times
    # as much when it keeps a random share of the pairs).
    lower = np.linalg.inv(np.linalg.cholesky(covariances))
    l00, l10, l11, l20, l21, l22 = (np.ascontiguousarray(lower[:, i, j]) for i, j in _LOWER)
    centre_columns = np.ascontiguousarray(centres.T)
    u = [moments.centroid[:, k].take(voxel) - centre_columns[k].take(taxel) for k in range(3)]
    y0 = l00.take(taxel) * u[0]
    y1 = l10.take(taxel) * u[0] + l11.take(taxel) * u[1]
    y2 = l20.take(taxel) * u[0] + l21.take(taxel) * u[1] + l22.take(taxel) * u[2]
    d2 = y0 * y0 + y1 * y1 + y2 * y2
    inside = np.flatnonzero(d2 < GATE_CHI2_3DOF_95)
    taxel, voxel, d2, y0, y1, y2 = (v.take(inside) for v in (taxel, voxel, d2, y0, y1, y2))
    if allowed is not None:
        keep = np.flatnonzero(allowed(taxel, voxel))
        taxel, voxel, d2, y0, y1, y2 = (v.take(keep) for v in (taxel, voxel, d2, y0, y1, y2))
    a0 = l00.take(taxel) * y0 + l10.take(taxel) * y1 + l20.take(taxel) * y2
    a1 = l11.take(taxel) * y1 + l21.take(taxel) * y2
    a2 = l22.take(taxel) * y2
    s00, s11, s22, s01, s02, s12 = (
        moments.scatter[:, i, j].take(voxel) for i, j in ((0, 0), (1, 1), (2, 2), *_OFF)
    )
    # S a, a^T S a and tr(C^-1 S) of the second-order term.
    scattered = (
        s00 * a0 + s01 * a1 + s02 * a2,
        s01 * a0 + s11 * a1 + s12 * a2,
        s02 * a0 + s12 * a1 + s22 * a2,
    )
    inverse = np.einsum("tki,tkj->tij", lower, lower)
    trace = (
        inverse[:, 0, 0].take(taxel) * s00
        + inverse[:, 1, 1].take(taxel) * s11
        + inverse[:, 2, 2].take(taxel) * s22
        + 2.0
        * (
            inverse[:, 0, 1].take(taxel) * s01
            + inverse[:, 0, 2].take(taxel) * s02
            + inverse[:, 1, 2].take(taxel) * s12
        )
    )
    curvature = a0 * scattered[0] + a1 * scattered[1] + a2 * scattered[2] - trace
    density = normaliser.take(taxel) * np.exp(-0.5 * d2)
    voxel_mass = density * (moments.count.take(voxel) + 0.5 * curvature)
    mass = np.bincount(taxel, weights=voxel_mass, minlength=count).astype(float)
    weighted_sum = np.stack(
        [
            np.bincount(
                taxel,
                weights=voxel_mass * moments.centroid[:, k].take(voxel) - density * scattered[k],
                minlength=count,
            )
            for k in range(3)
        ],
        axis=1,
    ).astype(float)
    inside_any = np.zeros(len(moments.count), dtype=bool)
    inside_any[voxel] = True
    return mass, weighted_sum, inside_any
