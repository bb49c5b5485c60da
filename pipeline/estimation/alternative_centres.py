"""The alternative correspondence centres of paper eq. 13: for each taxel the vector median
of the object points Mahalanobis-closest to it (:func:`alternative_centres`), found
exactly by Euclidean queries on the :class:`~.correspondences.PointIndex`."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.estimation.geometry import apply_side, invert_side, side_linear_part

if TYPE_CHECKING:
    from pipeline.estimation.correspondences import PointIndex

#: Object points whose vector median replaces the taxel in the alternative weights (eq. 13).
ALTERNATIVE_NEIGHBOURS = 5


def _mahalanobis_nearest(
    index: PointIndex,
    points: np.ndarray,
    centres_pre: np.ndarray,
    covariance_pre: np.ndarray,
    count: int,
    displacement_m: float,
    bound: np.ndarray | None = None,
    first: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` points with the smallest Mahalanobis distance to each centre, exactly.

    Euclidean k-nearest queries with growing k: once the k-th Euclidean distance ``d_k``
    (less the displacement bound) satisfies ``d_k^2 / lambda_max >= D2`` of the current
    ``count``-th best, no point outside the queried set can be Mahalanobis-closer.

    Args:
        bound: ``(M,)`` squared Mahalanobis distances beyond which the caller needs no
            point: a centre stops searching once nothing closer than its bound can remain,
            and its entries with ``D2 >= bound`` are then not guaranteed (they are reported,
            but a closer point may exist). None finds every centre's ``count`` exactly.
        first: the first round's Euclidean query, ``(M, k)`` distances and points for
            ``k = min(N, 4 count)`` (:func:`euclidean_nearest`), when the caller has made it.

    Returns:
        ``(M, count)`` point indices and their squared Mahalanobis distances, best first.
    """
    n_points, n_centres = len(points), len(centres_pre)
    count = min(count, n_points)
    inverse = np.linalg.inv(covariance_pre)
    lambda_max = np.linalg.eigvalsh(covariance_pre)[:, -1]
    limit = np.full(n_centres, np.inf) if bound is None else bound
    best_index = np.empty((n_centres, count), dtype=np.int64)
    best_d2 = np.empty((n_centres, count))
    todo = np.arange(n_centres)
    k = min(n_points, 4 * count)
    while todo.size:
        if first is None:
            distances, neighbours = euclidean_nearest(index, centres_pre[todo], k)
        else:
            (distances, neighbours), first = first, None
        offsets = points[neighbours] - centres_pre[todo][:, None, :]
        d2 = np.einsum("tki,tij,tkj->tk", offsets, inverse[todo], offsets)
        order = np.argsort(d2, axis=1)[:, :count]
        chosen_d2 = np.take_along_axis(d2, order, axis=1)
        outside = np.maximum(distances[:, -1] - displacement_m, 0.0) ** 2 / lambda_max[todo]
        needed = np.minimum(chosen_d2[:, -1], limit[todo])
        done = (needed <= outside) | (k >= n_points)
        best_index[todo[done]] = np.take_along_axis(neighbours, order, axis=1)[done]
        best_d2[todo[done]] = chosen_d2[done]
        todo = todo[~done]
        k = min(n_points, 4 * k)
    return best_index, best_d2


def euclidean_nearest(
    index: PointIndex, centres: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` Euclidean nearest reference points of each of ``centres`` ((M, 3)): ``(M, k)``
    distances and point indices, nearest first."""
    distances, neighbours = index.tree.query(centres, k=k)
    return distances.reshape(len(centres), k), neighbours.reshape(len(centres), k)


def vector_median(candidates: np.ndarray) -> np.ndarray:
    """Vector median of each set in ``(M, K, 3)``: the member with the least summed
    Euclidean distance to the others (Astola et al. 1990), shape (M, 3)."""
    distances = np.linalg.norm(candidates[:, :, None, :] - candidates[:, None, :, :], axis=-1)
    best = np.argmin(distances.sum(axis=2), axis=1)
    return candidates[np.arange(len(candidates)), best]


def alternative_centres(
    index: PointIndex,
    points: np.ndarray,
    g: np.ndarray,
    pivot_m: np.ndarray,
    taxels_m: np.ndarray,
    covariances: tuple[np.ndarray, np.ndarray],
    displacement_m: float,
) -> np.ndarray:
    """``T^_i`` of eq. 13 in frame R, (M, 3).

    The five closest points are taken from the whole completed model (front and back
    images together, each side measured with its own ``C_i``), so ``T^_i`` lies on the side
    that best explains the contact; this is why eq. 13 fails when front and back overlap
    (paper Fig. 4). The fifth-closest of each side's Euclidean five nearest bounds the
    search of both sides, so a side far from a taxel (the front for a taxel on the hidden
    back) costs one small query instead of a search through the whole cloud.
    """
    count = min(ALTERNATIVE_NEIGHBOURS, len(points))
    frames = []
    for back, covariance in zip((False, True), covariances, strict=True):
        linear = side_linear_part(g, back)
        covariance_pre = np.einsum("ji,mjk,kl->mil", linear, covariance, linear)
        frames.append((back, invert_side(taxels_m, g, pivot_m, back), covariance_pre))
    # Each side's Euclidean five nearest are the first of the 4 x 5 nearest that the search
    # of each side queries first: one query per side serves both (a query far from the
    # cloud, a taxel's other side, costs as much as the rest of the search).
    queried, five = [], []
    for _, centres_pre, covariance_pre in frames:
        queried.append(euclidean_nearest(index, centres_pre, min(len(points), 4 * count)))
        offsets = points[queried[-1][1][:, :count]] - centres_pre[:, None, :]
        five.append(np.einsum("tki,tij,tkj->tk", offsets, np.linalg.inv(covariance_pre), offsets))
    bound = np.sort(np.concatenate(five, axis=1), axis=1)[:, count - 1]
    images, distances = [], []
    for (back, centres_pre, covariance_pre), query in zip(frames, queried, strict=True):
        nearest, d2 = _mahalanobis_nearest(
            index, points, centres_pre, covariance_pre, count, displacement_m, bound, query
        )
        images.append(apply_side(points[nearest.ravel()], g, pivot_m, back).reshape(*d2.shape, 3))
        distances.append(d2)
    all_images = np.concatenate(images, axis=1)
    all_d2 = np.concatenate(distances, axis=1)
    closest = np.argsort(all_d2, axis=1)[:, :count]
    chosen = np.take_along_axis(all_images, closest[:, :, None], axis=1)
    return vector_median(chosen)
