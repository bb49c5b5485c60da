"""The stacked tactile measurement with frozen weights, and its Jacobian (paper eqs. 10-12).

Each (taxel, side) pair whose weight mass ``a`` is non-zero contributes one block of three
rows (taxel-major within a side, front blocks first). With normalised weights
``omega_n = w_n / a`` and the eq. 11 scale ``s``:

    h_block(x) = s * f(sum_n omega_n p_n)   ( = s * T~ ; f is affine so this equals
                                             s * sum_n omega_n f(p_n) )
    y_block    = s * T

Residual scaling (eq. 11): ``s_i = a_i / max_j a_j`` where the maximum runs over the taxels
of the *same side* (``s_mb,i = a_mb,i / max_j a_mb,j`` for the back). Normalising each side by
its own maximum gives the densest contact of either side unit scale even when the other side
has no support; the paper's text uses ``max_j a_b,j`` for both.

Weights and scales are constants of a :class:`FrozenMeasurement`; the IEKF recomputes them at
every iteration and differentiates with them held fixed (eq. 12). A measurement also keeps
each block's weighted mean at the points it was frozen at; when the points are held fixed
(Stage 1) that is all it needs, so its pair list may be left out (wide gates, see
:mod:`.correspondences`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse

from pipeline.estimation.correspondences import Correspondences
from pipeline.estimation.geometry import apply_side, side_jacobian, side_linear_part
from pipeline.estimation.indexsets import positions, union


@dataclass(frozen=True)
class FrozenMeasurement:
    """One linearisable measurement: row blocks, their pairs and their noise.

    Attributes:
        observed_m: ``(B, 3)`` the taxel position ``T_i`` of each block, frame R.
        back: ``(B,)`` True for a back (``f_mb``) block.
        taxel: ``(B,)`` index of the block's taxel within the grasp's contacts.
        scale: ``(B,)`` residual scale ``s`` of eq. 11.
        pair_block, pair_point: ``(K,)`` block and point index of each non-zero weight.
        pair_omega: ``(K,)`` normalised weights; they sum to one within a block.
        noise: ``(B, 3, 3)`` measurement covariance ``R_i`` of each block (m^2).
        means_m: ``(B, 3)`` ``sum_n omega_n p_n`` at the points the weights were computed
            for (unbiased frame R).
        complete: True when the pairs list every weight (empty pair arrays otherwise).
    """

    observed_m: np.ndarray
    back: np.ndarray
    taxel: np.ndarray
    scale: np.ndarray
    pair_block: np.ndarray
    pair_point: np.ndarray
    pair_omega: np.ndarray
    noise: np.ndarray
    means_m: np.ndarray
    complete: bool

    @property
    def n_blocks(self) -> int:
        return len(self.taxel)

    def observation(self) -> np.ndarray:
        """``y``: the scaled taxel positions, ``(3B,)``."""
        return (self.scale[:, None] * self.observed_m).ravel()


def freeze(
    correspondences: Correspondences, taxels_m: np.ndarray, noise: np.ndarray
) -> FrozenMeasurement:
    """Build the measurement of one iteration from its correspondences.

    Args:
        correspondences: weights of both sides.
        taxels_m: ``(M, 3)`` taxel positions.
        noise: ``(M, 3, 3)`` per-taxel ``R``.
    """
    blocks_taxel, blocks_back, blocks_scale, blocks_mean = [], [], [], []
    pair_block, pair_point, pair_omega = [], [], []
    complete = correspondences.complete()
    first_block = 0
    for side in correspondences.sides():
        supported = np.flatnonzero(side.mass > 0)
        if supported.size == 0:
            continue
        block_of_taxel = np.full(len(side.mass), -1, dtype=np.int64)
        block_of_taxel[supported] = first_block + np.arange(supported.size)
        blocks_taxel.append(supported)
        blocks_back.append(np.full(supported.size, side.back))
        blocks_scale.append(side.mass[supported] / side.mass.max())
        blocks_mean.append(side.weighted_sum[supported] / side.mass[supported, None])
        if complete:
            pair_block.append(block_of_taxel[side.taxel])
            pair_point.append(side.point)
            pair_omega.append(side.weight / side.mass[side.taxel])
        first_block += supported.size
    if not blocks_taxel:
        raise ValueError("no taxel has a correspondence; nothing to measure")
    taxel = np.concatenate(blocks_taxel)
    if not complete:
        pair_block = pair_point = [np.empty(0, dtype=np.int64)]
        pair_omega = [np.empty(0)]
    return FrozenMeasurement(
        observed_m=taxels_m[taxel],
        back=np.concatenate(blocks_back),
        taxel=taxel,
        scale=np.concatenate(blocks_scale),
        pair_block=np.concatenate(pair_block),
        pair_point=np.concatenate(pair_point),
        pair_omega=np.concatenate(pair_omega),
        noise=noise[taxel],
        means_m=np.concatenate(blocks_mean),
        complete=complete,
    )


def weighted_means(measurement: FrozenMeasurement, points: np.ndarray) -> np.ndarray:
    """``sum_n omega_n p_n`` of each block, in the unbiased point frame, (B, 3).

    Raises:
        ValueError: the measurement does not list its pairs.
    """
    if not measurement.complete:
        raise ValueError("the measurement's pairs were not listed; only its frozen means exist")
    weighted = measurement.pair_omega[:, None] * points[measurement.pair_point]
    return np.stack(
        [
            np.bincount(
                measurement.pair_block, weights=weighted[:, k], minlength=measurement.n_blocks
            )
            for k in range(3)
        ],
        axis=1,
    )


def predict(
    measurement: FrozenMeasurement, g: np.ndarray, points: np.ndarray, pivot_m: np.ndarray
) -> np.ndarray:
    """``h(x)``: scaled predicted taxel positions, (3B,)."""
    means = weighted_means(measurement, points)
    predicted = np.empty_like(means)
    for back in (False, True):
        rows = measurement.back == back
        predicted[rows] = apply_side(means[rows], g, pivot_m, back)
    return (measurement.scale[:, None] * predicted).ravel()


@dataclass(frozen=True)
class PointJacobian:
    """The point columns of ``H``: block (b, n) is ``coefficient * block_matrix[b]``.

    Attributes:
        pair_block, pair_point: ``(K,)`` as in :class:`FrozenMeasurement`.
        coefficient: ``(K,)`` ``s_b * omega_n``.
        block_matrix: ``(B, 3, 3)`` ``d f / d p`` of the block's side (``R_z`` or
            ``R_z (I - 2 n n^T)``).
    """

    pair_block: np.ndarray
    pair_point: np.ndarray
    coefficient: np.ndarray
    block_matrix: np.ndarray

    @property
    def n_blocks(self) -> int:
        return len(self.block_matrix)

    def points(self) -> np.ndarray:
        """Sorted indices of the points with a non-zero column block."""
        return union(self.pair_point)

    def times_displacement(self, points: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """``H_p (points - reference)`` using only the rows of the pair points, (3B,)."""
        delta = points[self.pair_point] - reference[self.pair_point]
        weighted = self.coefficient[:, None] * delta
        summed = np.stack(
            [np.bincount(self.pair_block, weighted[:, k], self.n_blocks) for k in range(3)], axis=1
        )
        return np.einsum("bij,bj->bi", self.block_matrix, summed).ravel()

    def weighted_gram(self, local_points: np.ndarray, variance: np.ndarray) -> np.ndarray:
        """``H_p D H_p^T`` for ``D = diag(variance) (x) I_3`` over ``local_points``, (3B, 3B).

        With isotropic point blocks the product factors into the scalar Gram matrix
        ``G = C diag(variance) C^T`` of the pair coefficients (B x B, one sparse product
        with K non-zeros) and block ``(b, c) = G_bc M_b M_c^T``; forming ``H_p`` with its
        3 x 3 blocks would cost nine times the memory and 27 times the arithmetic.

        Args:
            local_points: sorted indices of the points with a column block.
            variance: ``(U,)`` isotropic variance of each of those points (m^2).
        """
        local = positions(local_points, self.pair_point)
        shape = (self.n_blocks, len(local_points))
        coefficients = scipy.sparse.csr_matrix((self.coefficient, (self.pair_block, local)), shape)
        gram = (coefficients.multiply(variance[None, :]) @ coefficients.T).toarray()
        stacked = self.block_matrix.reshape(3 * self.n_blocks, 3)
        # (stacked @ stacked.T) holds M_b M_c^T in block (b, c).
        return (stacked @ stacked.T) * np.repeat(np.repeat(gram, 3, axis=0), 3, axis=1)

    def transpose_times(self, local_points: np.ndarray, vector: np.ndarray) -> np.ndarray:
        """``H_p^T v`` over ``local_points`` (sorted), for ``v`` of shape (3B,); (U, 3)."""
        local = positions(local_points, self.pair_point)
        per_block = np.einsum("bji,bj->bi", self.block_matrix, vector.reshape(-1, 3))
        per_pair = self.coefficient[:, None] * per_block[self.pair_block]
        return np.stack(
            [np.bincount(local, per_pair[:, k], len(local_points)) for k in range(3)], axis=1
        )

    def sparse(self, local_points: np.ndarray) -> scipy.sparse.csr_matrix:
        """``H_p`` restricted to the columns of ``local_points`` (sorted), (3B, 3U)."""
        local = positions(local_points, self.pair_point)
        values = self.coefficient[:, None, None] * self.block_matrix[self.pair_block]
        rows = 3 * self.pair_block[:, None, None] + np.arange(3)[None, :, None]
        cols = 3 * local[:, None, None] + np.arange(3)[None, None, :]
        rows, cols = np.broadcast_arrays(rows, cols)
        shape = (3 * self.n_blocks, 3 * len(local_points))
        return scipy.sparse.csr_matrix((values.ravel(), (rows.ravel(), cols.ravel())), shape=shape)

    def dense(self, n_points: int) -> np.ndarray:
        """``H_p`` over all ``N`` points, (3B, 3N) (the dense reference only)."""
        return self.sparse(np.arange(n_points)).toarray()


@dataclass(frozen=True)
class Linearisation:
    """``h(x_i)`` and ``H_i`` of one iteration.

    Attributes:
        prediction: ``(3B,)`` ``h(x_i)``.
        bias_plane_jacobian: ``(3B, len(g))`` columns of ``g``.
        point_jacobian: point columns, or None when the points are held fixed (Stage 1).
    """

    prediction: np.ndarray
    bias_plane_jacobian: np.ndarray
    point_jacobian: PointJacobian | None


def linearise(
    measurement: FrozenMeasurement,
    g: np.ndarray,
    points: np.ndarray,
    pivot_m: np.ndarray,
    with_points: bool,
) -> Linearisation:
    """Evaluate ``h`` and its Jacobian at ``(g, points)`` with the weights frozen (eq. 12).

    With ``with_points`` False the points are those the measurement was frozen at (Stage 1
    holds them fixed) and its stored block means are used; otherwise the means are
    recomputed from the pairs at ``points``.
    """
    means = weighted_means(measurement, points) if with_points else measurement.means_m
    predicted = np.empty_like(means)
    jacobian_g = np.empty((measurement.n_blocks, 3, len(g)))
    block_matrix = np.empty((measurement.n_blocks, 3, 3))
    for back in (False, True):
        rows = measurement.back == back
        predicted[rows] = apply_side(means[rows], g, pivot_m, back)
        jacobian_g[rows] = side_jacobian(means[rows], g, pivot_m, back)
        block_matrix[rows] = side_linear_part(g, back)
    scale = measurement.scale
    point_jacobian = None
    if with_points:
        point_jacobian = PointJacobian(
            pair_block=measurement.pair_block,
            pair_point=measurement.pair_point,
            coefficient=scale[measurement.pair_block] * measurement.pair_omega,
            block_matrix=block_matrix,
        )
    return Linearisation(
        prediction=(scale[:, None] * predicted).ravel(),
        bias_plane_jacobian=(scale[:, None, None] * jacobian_g).reshape(-1, len(g)),
        point_jacobian=point_jacobian,
    )
