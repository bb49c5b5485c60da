"""Taxel-to-point correspondence weights (paper eqs. 9, 11 and 13; docs/method.md §2).

For each taxel ``i`` and each side (front ``f_b``, back ``f_mb``) the weights are Gaussian
densities ``w = N(f(p_n); centre_i, C_i)`` gated at the chi-square(3) 95 % quantile
``D2 < 7.815``. The centre is the taxel itself (eq. 9, "standard") or the vector median of
the five object points Mahalanobis-closest to it (eq. 13, "alternative",
:mod:`.alternative_centres`).

One module because the listed, whole-cloud and voxel-aggregated paths below compute the
same weights and must stay interchangeable (which one a taxel takes changes only the
speed), and all three rest on :class:`PointIndex`'s bound on how far points have moved.

Search strategy: both sides' maps are isometries, so a taxel's gate is searched around its
*pre-image* (``f^-1`` of the centre) among the unmoved points, in one
:class:`scipy.spatial.cKDTree` built once over the points' reference positions. Points that
the filter has moved since (Stage 2) are covered by widening the search radius by the
largest displacement so far, and every candidate is then tested exactly at its current
position. The cost of a search therefore grows with N only through the tree queries and the
number of points that really fall inside the gates. While the points stay put (Stage 1) a
side keeps its gates' candidates from one call to the next and searches again only when a
bound on the gates' motion no longer proves that they hold every point of the new gates
(:mod:`.gate_candidates`).

Wide gates: before the first update the back's gates span the whole object (a prior ``m_r``
std of tens of millimetres), so listing every (taxel, point) pair would cost ``O(M N)``
memory. When the caller does not need the pairs (Stage 1 holds the points fixed and only
needs each taxel's weight mass and weighted mean), taxels whose gate radius exceeds
:data:`WIDE_GATE_FRACTION` of the cloud's bounding-box diagonal are summed over the whole
cloud in blocks instead (whitened coordinates through one matrix product), which is exact and
needs ``O(M)`` memory. Which taxels take which path changes only the speed, never a weight.
Faster still, and what Stage 1 normally uses while no point has moved: when the gates are
wide enough that a voxel grid fine enough for them (:mod:`.aggregation`) holds at most
:data:`AGGREGATE_FRACTION` as many voxels as there are points, every taxel is summed over the
voxel moments (second-order accurate, errors well under 1 % of the mass); narrower gates
take the exact paths above.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from itertools import chain

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from pipeline.estimation.aggregation import (
    GATE_CHI2_3DOF_95,
    VoxelMoments,
    gaussian_sums,
    voxel_exponents,
)
from pipeline.estimation.aggregation import voxel_moments as _voxel_moments
from pipeline.estimation.alternative_centres import alternative_centres
from pipeline.estimation.covariances import correspondence_covariances
from pipeline.estimation.gate_candidates import CANDIDATE_REACH, GateCandidates
from pipeline.estimation.geometry import box_corners, invert_side, side_jacobian, side_linear_part
from pipeline.estimation.indexsets import ranks, union, unique_inverse
from pipeline.estimation.surface import any_azimuth, compatible, facing_labels, point_labels

#: A gate whose radius exceeds this fraction of the cloud's bounding-box diagonal is summed
#: over the whole cloud instead of listed pair by pair (when the pairs are not needed).
WIDE_GATE_FRACTION = 0.25
#: Points per block of the whole-cloud sums (bounds their temporary memory).
_SUM_BLOCK_POINTS = 4096
#: Voxel edge of the centroids whose convex hull bounds the cloud (m), see PointIndex.hull.
HULL_VOXEL_M = 0.005
#: Unlisted sums go through the voxel-aggregated cloud when it has at most this fraction of
#: the points (see :mod:`.aggregation`); otherwise the gates are too narrow for it to pay.
AGGREGATE_FRACTION = 0.5


class PointIndex:
    """A KD-tree over the points' reference positions that tolerates later moves.

    Args:
        reference_points: ``(N, 3)`` positions the tree is built on (kept by reference;
            the caller must not modify the array).
        tree: a KD-tree already built over ``reference_points`` (None builds one).
    """

    def __init__(self, reference_points: np.ndarray, tree: cKDTree | None = None) -> None:
        self.reference = reference_points
        self.tree = cKDTree(reference_points, balanced_tree=False) if tree is None else tree
        self.diagonal_m = float(np.linalg.norm(self.tree.maxes - self.tree.mins))
        self._moved = np.empty(0, dtype=np.int64)
        self._moments: dict[tuple[tuple[int, ...], bool | None], VoxelMoments] = {}
        self._labels: dict[bool, np.ndarray] = {}
        self._hull: tuple[np.ndarray, float] | None = None
        self._ranks: list[tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]] = []
        #: Gate candidates kept per caller's key (GateCandidates), and what each key's last
        #: call searched (see :meth:`steady`).
        self.candidates: dict[object, GateCandidates] = {}
        self._searched: dict[object, object] = {}
        self._columns: np.ndarray | None = None

    def labels(self, azimuth: bool) -> np.ndarray:
        """Facing label of every reference point (:func:`~.surface.point_labels`), cached;
        without ``azimuth`` only the elevation band is kept (:func:`~.surface.any_azimuth`)."""
        if not self._labels:
            self._labels[True] = point_labels(self.reference)
            self._labels[False] = any_azimuth(self._labels[True])
        return self._labels[azimuth]

    def label_ranks(self, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~.indexsets.ranks` of one of :meth:`labels`' arrays, cached (the listed
        gates look every candidate's label up by its rank; every voxel grid splits its
        cells by them)."""
        for array, found in self._ranks:
            if array is labels:
                return found
        self._ranks.append((labels, ranks(labels)))
        return self._ranks[-1][1]

    def steady(self, key: object, searched: object) -> bool:
        """Record what ``key``'s gates now search (``searched``: how many listed gates) and
        tell whether its last call searched the same. Keeping candidates costs a wider
        search, which pays only when the next call tests the same gates: the first listed
        call after a change (the first of a pass, after sums over voxels) searches
        plainly, the second keeps its candidates."""
        same = self._searched.get(key) == searched
        self._searched[key] = searched
        return same

    def columns(self, points: np.ndarray) -> np.ndarray:
        """``points`` as ``(3, N)`` contiguous coordinates, cached for the reference
        positions (the listed gates gather candidates one coordinate at a time)."""
        if points is not self.reference:
            return np.ascontiguousarray(points.T)
        if self._columns is None:
            self._columns = np.ascontiguousarray(self.reference.T)
        return self._columns

    def moments(self, exponents: np.ndarray, azimuth: bool | None) -> VoxelMoments:
        """Voxel moments of the reference points for edges ``2^(exponents / 4)`` (m), cached
        (see :func:`~.aggregation.voxel_exponents`); points of different :meth:`labels`
        ``(azimuth)`` never share a voxel, and with ``azimuth`` None labels are ignored."""
        key = (tuple(int(e) for e in exponents), azimuth)
        if key not in self._moments:
            labels = None if azimuth is None else self.labels(azimuth)
            self._moments[key] = _voxel_moments(
                self.reference,
                np.exp2(exponents / 4.0),
                labels,
                self.columns(self.reference),
                None if labels is None else self.label_ranks(labels),
            )
        return self._moments[key]

    def hull(self) -> tuple[np.ndarray, float]:
        """A convex polytope and a margin that together hold every reference point, cached.

        The vertices of the convex hull of the points' :data:`HULL_VOXEL_M` voxel centroids
        and the largest distance of a point from its voxel's centroid: every point is within
        that margin of the polytope (qhull over the centroids instead of the points: 8 ms
        instead of 13 ms at 20,000 points, 30 instead of 65 ms at 100,000). Degenerate
        centroids (flat, too few) give the bounding box's corners and no margin.
        """
        if self._hull is None:
            cells = np.floor(self.reference / HULL_VOXEL_M).astype(np.int64)
            cells -= cells.min(axis=0)
            keys = np.ravel_multi_index(cells.T, tuple(int(e) + 1 for e in cells.max(axis=0)))
            _, voxel, count = unique_inverse(keys)
            centroids = np.stack(
                [np.bincount(voxel, self.reference[:, k]) / count for k in range(3)], axis=1
            )
            try:
                vertices = centroids[ConvexHull(centroids).vertices]
                margin_m = float(np.max(np.linalg.norm(self.reference - centroids[voxel], axis=1)))
                self._hull = (vertices, margin_m)
            except QhullError:
                self._hull = (box_corners(self.tree.mins, self.tree.maxes), 0.0)
        return self._hull

    def note_moved(self, indices: np.ndarray) -> None:
        """Record that the points ``indices`` may now differ from their reference position."""
        self._moved = union(self._moved, indices)

    def displacement_bound(self, points: np.ndarray, indices: np.ndarray | None = None) -> float:
        """Largest distance (m) between a point's current and reference position, over
        every point noted as moved plus ``indices``."""
        moved = self._moved if indices is None else union(self._moved, indices)
        if moved.size == 0:
            return 0.0
        return float(np.max(np.linalg.norm(points[moved] - self.reference[moved], axis=1)))


@dataclass(frozen=True)
class SideCorrespondences:
    """Gated weights of one side for all taxels, as (taxel, point) pairs plus per-taxel sums.

    Attributes:
        back: True for the mirrored side ``f_mb``, False for the front ``f_b``.
        taxel, point: ``(K,)`` indices of each listed pair with a non-zero weight.
        weight: ``(K,)`` Gaussian density ``N(f(p); centre, C)`` (1/m^3).
        mass: ``(M,)`` per-taxel sum of weights, ``a_i`` of eq. 11.
        weighted_sum: ``(M, 3)`` per-taxel ``sum_n w_n p_n`` over the current (unbiased)
            points, frame R (m/m^3).
        complete: True when the pairs list every non-zero weight; False when wide gates
            were summed without listing them (see the module docstring).
        wide_active: sorted indices of the points inside some unlisted (wide) gate.
    """

    back: bool
    taxel: np.ndarray
    point: np.ndarray
    weight: np.ndarray
    mass: np.ndarray
    weighted_sum: np.ndarray
    complete: bool
    wide_active: np.ndarray


@dataclass(frozen=True)
class Correspondences:
    """Front and back correspondences of one iteration.

    Attributes:
        front, back: the two sides.
        alternative: True when the eq. 13 (vector-median) centres were used.
    """

    front: SideCorrespondences
    back: SideCorrespondences
    alternative: bool

    def sides(self) -> tuple[SideCorrespondences, SideCorrespondences]:
        return (self.front, self.back)

    def supported_taxels(self) -> np.ndarray:
        """``(M,)`` bool: taxels with a non-zero weight on either side."""
        return (self.front.mass > 0) | (self.back.mass > 0)

    def complete(self) -> bool:
        """True when both sides list every non-zero weight as a pair."""
        return self.front.complete and self.back.complete

    def active_points(self) -> np.ndarray:
        """Sorted indices of the points inside some taxel's gate (the active set A)."""
        listed = [side.point for side in self.sides()] + [s.wide_active for s in self.sides()]
        return union(*listed)


def exclusive_sides(correspondences: Correspondences) -> Correspondences:
    """Keep, for every taxel, only the side with the larger weight mass.

    A taxel touches one surface, front or back. With a broad prior on ``m_r`` the back's
    gate reaches through the object, so under eq. 11 a front taxel also gets a residual
    against the far side and the two pull the state in opposite directions; explaining each
    taxel by its better-supported side removes that conflict (ties go to the front).
    """
    keep_front = correspondences.front.mass >= correspondences.back.mass
    sides = []
    for side, keep in zip(correspondences.sides(), (keep_front, ~keep_front), strict=True):
        pairs = keep[side.taxel]
        sides.append(
            SideCorrespondences(
                back=side.back,
                taxel=side.taxel[pairs],
                point=side.point[pairs],
                weight=side.weight[pairs],
                mass=np.where(keep, side.mass, 0.0),
                weighted_sum=np.where(keep[:, None], side.weighted_sum, 0.0),
                complete=side.complete,
                wide_active=side.wide_active,
            )
        )
    return Correspondences(front=sides[0], back=sides[1], alternative=correspondences.alternative)


def every_pad_supported(correspondences: Correspondences, pads: np.ndarray) -> bool:
    """Hybrid-schedule switch: every pad in contact has more than one supported taxel."""
    supported = correspondences.supported_taxels()
    return all(np.count_nonzero(supported[pads == pad]) > 1 for pad in np.unique(pads))


def side_covariances(
    taxels_m: np.ndarray,
    window: np.ndarray,
    g: np.ndarray,
    pivot_m: np.ndarray,
    state_covariance: np.ndarray,
    back: bool,
) -> np.ndarray:
    """World-frame ``C_i = C_t + J P J^T`` of one side, (M, 3, 3).

    The Jacobian of the side's map is evaluated at the taxel's pre-image, the point that
    would sit exactly at the taxel: ``C_i`` is a property of the taxel's window, shared by
    all its candidates.
    """
    preimages = invert_side(taxels_m, g, pivot_m, back)
    jacobians = side_jacobian(preimages, g, pivot_m, back)
    return correspondence_covariances(window, jacobians, state_covariance)


def _gate_distances(
    columns: np.ndarray,
    point: np.ndarray,
    counts: np.ndarray,
    centres: np.ndarray,
    inverse: np.ndarray,
) -> np.ndarray:
    """Squared Mahalanobis distance ``d^T C^-1 d`` of each candidate from its centre.

    The candidates come centre by centre (``counts`` of each, ``point`` their indices), so
    a centre's coordinates and entries of ``inverse`` ((T, 3, 3)) are repeated along its
    run rather than gathered per pair, and the points' coordinates are gathered one
    contiguous column of ``columns`` ((3, N)) at a time: with tens of thousands of
    candidates per call, gathering ``(K, 3)`` rows and ``(K, 9)`` matrix entries cost more
    than the arithmetic.
    """
    entries = inverse.reshape(-1, 9)

    def along_runs(values: np.ndarray) -> np.ndarray:
        return np.repeat(values, counts)

    dx, dy, dz = (columns[k].take(point) - along_runs(centres[:, k]) for k in range(3))
    return (
        along_runs(entries[:, 0]) * dx * dx
        + along_runs(entries[:, 4]) * dy * dy
        + along_runs(entries[:, 8]) * dz * dz
        + 2.0
        * (
            along_runs(entries[:, 1]) * dx * dy
            + along_runs(entries[:, 2]) * dx * dz
            + along_runs(entries[:, 5]) * dy * dz
        )
    )


def _searched(
    index: PointIndex, centres: np.ndarray, radii_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each centre's points within its radius on the tree: ``(T,)`` counts and the
    ``(K,)`` points, centre by centre."""
    neighbours = index.tree.query_ball_point(centres, radii_m, return_sorted=False)
    counts = np.fromiter(map(len, neighbours), dtype=np.int64, count=len(neighbours))
    # One pass over the lists (an array per list costs more than the search at 100k points).
    point = np.fromiter(chain.from_iterable(neighbours), dtype=np.int64, count=int(counts.sum()))
    return counts, point


def _gated_weights(
    index: PointIndex,
    columns: np.ndarray,
    centres_pre: np.ndarray,
    covariance_pre: np.ndarray,
    radii_m: np.ndarray,
    normaliser: np.ndarray,
    allowed: Callable[[np.ndarray, np.ndarray], np.ndarray] | None,
    key: object = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (taxel, point, density) inside each centre's gate, in the pre-image frame.

    Each centre's ball of radius ``radii_m`` (its gate's largest semi-axis plus the
    displacement bound) is searched on the tree, then every candidate is tested exactly on
    ``columns`` (the current points' ``(3, N)`` coordinates, :meth:`PointIndex.columns`)
    and, with ``allowed(taxel, point)``, by the surface filter. With a ``key`` (the points
    unmoved) the candidates within :data:`CANDIDATE_REACH` are kept in the index under it,
    and the next call with that key tests them instead of searching again while they
    cover its gates (:class:`~.gate_candidates.GateCandidates`; the tree lists a centre's
    points in its own order whatever the radius, so the pairs even come in the same order
    as a search's).
    """
    if len(centres_pre) == 0:
        empty = np.empty(0, dtype=np.int64)
        return empty, empty, np.empty(0)
    inverse = np.linalg.inv(covariance_pre)
    kept = index.candidates.get(key) if key is not None else None
    if kept is not None and kept.covers(centres_pre, inverse):
        counts, point = kept.counts, kept.point
        d2 = _gate_distances(columns, point, counts, centres_pre, inverse)
    elif key is None:
        counts, point = _searched(index, centres_pre, radii_m)
        d2 = _gate_distances(columns, point, counts, centres_pre, inverse)
    else:
        reach = CANDIDATE_REACH / np.sqrt(GATE_CHI2_3DOF_95)
        counts, point = _searched(index, centres_pre, reach * radii_m)
        d2 = _gate_distances(columns, point, counts, centres_pre, inverse)
        near = d2 < CANDIDATE_REACH**2
        taxel = np.repeat(np.arange(len(centres_pre)), counts)
        counts = np.bincount(taxel[near], minlength=len(centres_pre))
        point, d2 = point[near], d2[near]
        lower = np.linalg.cholesky(covariance_pre)
        index.candidates[key] = GateCandidates(centres_pre.copy(), lower, counts, point)
    taxel = np.repeat(np.arange(len(centres_pre)), counts)
    gated = np.flatnonzero(d2 < GATE_CHI2_3DOF_95)
    taxel, point = taxel.take(gated), point.take(gated)
    if allowed is not None:
        keep = np.flatnonzero(allowed(taxel, point))
        taxel, point, gated = taxel.take(keep), point.take(keep), gated.take(keep)
    return taxel, point, normaliser.take(taxel) * np.exp(-0.5 * d2.take(gated))


def _summed_weights(
    points: np.ndarray,
    centres_pre: np.ndarray,
    covariance_pre: np.ndarray,
    normaliser: np.ndarray,
    bands: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-centre weight mass and ``sum w p`` over every point, without listing pairs.

    Points are whitened for all centres at once (``L_i^-1 p`` for ``C_i = L_i L_i^T``, one
    matrix product per block of points), so ``D2 = |L_i^-1 (p - c_i)|^2`` exactly.

    Returns:
        ``(T,)`` masses, ``(T, 3)`` weighted sums and the sorted indices of the points
        inside some gate.
    """
    count = len(centres_pre)
    whitening = np.linalg.inv(np.linalg.cholesky(covariance_pre))
    # Columns 3 t + k hold row k of L_t^-1, so (p @ stacked)[3 t + k] = (L_t^-1 p)_k.
    stacked = whitening.transpose(2, 0, 1).reshape(3, 3 * count)
    whitened_centres = np.einsum("tij,tj->ti", whitening, centres_pre).ravel()
    mass = np.zeros(count)
    weighted_sum = np.zeros((count, 3))
    inside_any = np.zeros(len(points), dtype=bool)
    for first in range(0, len(points), _SUM_BLOCK_POINTS):
        block = points[first : first + _SUM_BLOCK_POINTS]
        offsets = block @ stacked - whitened_centres
        offsets *= offsets
        d2 = offsets[:, 0::3] + offsets[:, 1::3] + offsets[:, 2::3]
        inside = d2 < GATE_CHI2_3DOF_95
        if bands is not None:
            inside &= compatible(bands[0][first : first + len(block), None], bands[1][None, :])
        weights = np.exp(-0.5 * d2)
        weights[~inside] = 0.0
        weights *= normaliser
        mass += weights.sum(axis=0)
        weighted_sum += weights.T @ block
        inside_any[first : first + len(block)] = inside.any(axis=1)
    return mass, weighted_sum, np.flatnonzero(inside_any)


def _compatible_pairs(
    member_labels: tuple[np.ndarray, np.ndarray], taxel_label: np.ndarray
) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``allowed(taxel, member)`` of :func:`~.aggregation.gaussian_sums` (members: voxels)
    and :func:`_gated_weights` (members: points): the surface filter's
    :func:`~.surface.compatible` test, looked up in a table over the few distinct labels
    (a pair costs two gathers instead of the test's dozen array operations).

    Args:
        member_labels: the distinct labels of the members and each member's index among
            them (``np.unique(labels, return_inverse=True)``).
        taxel_label: ``(T,)`` the taxels' labels.
    """
    member_values, member_index = member_labels
    taxel_values, taxel_index = np.unique(taxel_label, return_inverse=True)
    table = compatible(member_values[:, None], taxel_values[None, :])

    def allowed(taxel: np.ndarray, member: np.ndarray) -> np.ndarray:
        return table[member_index.take(member), taxel_index.take(taxel)]

    return allowed


def _side_weights(
    index: PointIndex,
    points: np.ndarray,
    back: bool,
    centres_pre: np.ndarray,
    covariance_pre: np.ndarray,
    displacement_m: float,
    need_pairs: bool,
    bands: tuple[np.ndarray, np.ndarray] | None,
    key: object = None,
) -> SideCorrespondences:
    # Nine parameters: a numeric kernel given one side's gates and the points as arrays.
    """One side's weights: listed pairs for ordinary gates; without ``need_pairs``, sums over
    the voxel-aggregated cloud (unmoved points, gates wide enough) or whole-cloud sums for
    wide gates. ``bands``: (point, taxel) labels of the surface filter (:mod:`.surface`;
    azimuth on the front only), or None. ``key``: the listed gates' candidates are kept
    under it for the next call with the same key while the points are unmoved
    (:class:`~.gate_candidates.GateCandidates`); None searches afresh."""
    eigenvalues = np.linalg.eigvalsh(covariance_pre)
    radii = np.sqrt(GATE_CHI2_3DOF_95 * eigenvalues[:, -1]) + displacement_m
    normaliser = 1.0 / np.sqrt((2.0 * np.pi) ** 3 * np.prod(eigenvalues, axis=1))
    count = len(centres_pre)
    if not need_pairs and displacement_m == 0.0 and count:
        moments = index.moments(
            voxel_exponents(covariance_pre), None if bands is None else not back
        )
        if len(moments.count) <= AGGREGATE_FRACTION * len(points):
            allowed = None
            if bands is not None:
                allowed = _compatible_pairs(ranks(moments.label), bands[1])
            mass, weighted_sum, inside = gaussian_sums(
                moments, centres_pre, covariance_pre, normaliser, allowed
            )
            empty = np.empty(0, dtype=np.int64)
            wide_active = np.flatnonzero(inside[moments.voxel_of_point])
            return SideCorrespondences(
                back, empty, empty, np.empty(0), mass, weighted_sum, False, wide_active
            )
    wide = np.zeros(count, dtype=bool)
    if not need_pairs:
        wide = radii > WIDE_GATE_FRACTION * index.diagonal_m
    listed = np.flatnonzero(~wide)
    columns = index.columns(points)
    unmoved = key is not None and displacement_m == 0.0 and points is index.reference
    allowed = None
    if bands is not None:
        allowed = _compatible_pairs(index.label_ranks(bands[0]), bands[1][listed])
    taxel, point, weight = _gated_weights(
        index,
        columns,
        centres_pre[listed],
        covariance_pre[listed],
        radii[listed],
        normaliser[listed],
        allowed,
        key if unmoved and index.steady(key, ("listed", len(listed))) else None,
    )
    taxel = listed.take(taxel)
    # float64 even without pairs (bincount of nothing is an integer array).
    mass = np.bincount(taxel, weights=weight, minlength=count).astype(float)
    weighted_sum = np.stack(
        [
            np.bincount(taxel, weights=weight * columns[k].take(point), minlength=count)
            for k in range(3)
        ],
        axis=1,
    ).astype(float)
    wide_active = np.empty(0, dtype=np.int64)
    if wide.any():
        summed = np.flatnonzero(wide)
        mass[summed], weighted_sum[summed], wide_active = _summed_weights(
            points,
            centres_pre[summed],
            covariance_pre[summed],
            normaliser[summed],
            None if bands is None else (bands[0], bands[1][summed]),
        )
    return SideCorrespondences(
        back, taxel, point, weight, mass, weighted_sum, not wide.any(), wide_active
    )


def find_correspondences(
    index: PointIndex,
    points: np.ndarray,
    g: np.ndarray,
    pivot_m: np.ndarray,
    taxels_m: np.ndarray,
    window: np.ndarray,
    state_covariance: np.ndarray,
    alternative: bool,
    need_pairs: bool = True,
    taxel_normals: np.ndarray | None = None,
    facing_g: np.ndarray | None = None,
) -> Correspondences:
    # Eleven parameters: a numeric kernel given the state, the taxels and the gates as arrays.
    """Weights of every taxel against the front and back images of the current points.

    Args:
        index: KD-tree over the points' reference positions.
        points: ``(N, 3)`` current object points (unbiased, frame R).
        g: current ``(b_theta, b_x, b_y, b_z, m_r, m_theta)``.
        pivot_m: the bias pivot ``c``.
        taxels_m: ``(M, 3)`` taxel positions in contact, frame R.
        window: ``(M, 3, 3)`` taxel windows ``C_t``.
        state_covariance: ``(6, 6)`` covariance of ``g`` propagated into ``C_i``.
        alternative: use the eq. 13 centres instead of the taxels (eq. 9).
        need_pairs: list every non-zero weight as a pair (needed to differentiate with
            respect to the points); False lets wide gates be summed without listing.
        taxel_normals: ``(M, 3)`` unit taxel normals, frame R; when given a taxel only
            weighs points whose surface faces like it (:mod:`.surface`); None weighs all.
        facing_g: the state whose bias yaw turns the taxel normals into the points' frame
            for that filter; None uses ``g``. The IEKF passes the state a pass started
            from, so the filter, and with it the objective, stays fixed while the pass
            iterates.
    """
    displacement_m = index.displacement_bound(points)
    covariances = tuple(
        side_covariances(taxels_m, window, g, pivot_m, state_covariance, back)
        for back in (False, True)
    )
    centres = (
        alternative_centres(index, points, g, pivot_m, taxels_m, covariances, displacement_m)
        if alternative
        else taxels_m
    )
    sides = []
    for back, covariance in zip((False, True), covariances, strict=True):
        linear = side_linear_part(g, back)
        covariance_pre = np.einsum("ji,mjk,kl->mil", linear, covariance, linear)
        centres_pre = invert_side(centres, g, pivot_m, back)
        bands = None
        if taxel_normals is not None:
            # Taxel normals in the points' frame (row form of L^T nu); azimuth on the front only.
            facing_linear = linear if facing_g is None else side_linear_part(facing_g, back)
            bands = (
                index.labels(azimuth=not back),
                facing_labels(taxel_normals @ facing_linear, with_azimuth=not back),
            )
        sides.append(
            _side_weights(
                index,
                points,
                back,
                centres_pre,
                covariance_pre,
                displacement_m,
                need_pairs,
                bands,
                (back, alternative),
            )
        )
    return Correspondences(front=sides[0], back=sides[1], alternative=alternative)
