"""The IEKF covariance kept in structured form (docs/method.md §3, "structure").

``P`` of the full state ``(g, p_1 .. p_N)`` is never formed. It is held as

    P = B - sum_k V_k^T V_k

* ``B``: block diagonal, a dense (G, G) block for ``g = (b, m)`` (G = 6, or 7 for a plane
  of any orientation: :mod:`.geometry`; the prior plus every
  re-grasp noise ``Q``) and ``sigma_n^2 I_3`` for each point (the sensor noise);
* one downdate ``V_k = L_k^-1 H_k P_k^-`` per committed grasp (``S_k = L_k L_k^T`` the
  innovation covariance, Cholesky), whose columns cover only ``g`` and the points that grasp
  coupled (its active set and those of earlier grasps).

This is the covariance "dense over (b, m) and the active points, 3x3 blocks for every other
point" in factored form: the dense block over (b, m) u A equals ``B - sum V^T V`` restricted
to those columns (:meth:`StructuredCovariance.dense` materialises it for tests), but its
cost is ``O(rows x |A|)`` in memory and ``O(rows^2 x |A| + rows^3)`` in time instead of
``O(|A|^2)`` and ``O(rows x |A|^2)``. Nothing here touches a point outside (b, m) u A, so
time and memory do not grow with N.

The update is the symmetric form ``P+ = P- - (L^-1 H P-)^T (L^-1 H P-)``, which equals
``(I - K H) P-`` for the Kalman gain ``K = P- H^T S^-1`` and stays symmetric by
construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse

from pipeline.estimation.indexsets import union
from pipeline.estimation.measurement import Linearisation


def block_diagonal(blocks: np.ndarray) -> np.ndarray:
    """Dense block-diagonal matrix from ``(B, 3, 3)`` blocks, (3B, 3B)."""
    count = len(blocks)
    matrix = np.zeros((count, 3, count, 3))
    matrix[np.arange(count), :, np.arange(count), :] = blocks
    return matrix.reshape(3 * count, 3 * count)


def noise_matrix(noise: np.ndarray) -> np.ndarray:
    """A measurement's noise as one ``(3B, 3B)`` matrix: ``(B, 3, 3)`` per-block covariances
    go on the diagonal; a ``(3B, 3B)`` matrix (errors that blocks share) is taken as is."""
    noise = np.asarray(noise, dtype=float)
    return noise if noise.ndim == 2 else block_diagonal(noise)


def columns3(positions: np.ndarray) -> np.ndarray:
    """State columns ``3 u + (0, 1, 2)`` of local point positions ``u``, flattened."""
    return (3 * positions[:, None] + np.arange(3)[None, :]).ravel()


@dataclass(frozen=True)
class _Downdate:
    """``V`` (rows x (G + 3 |points|)) and the sorted point indices of its point columns;
    ``points is None`` when only the (b, m) columns were kept."""

    factor: np.ndarray
    points: np.ndarray | None


class StructuredGain:
    """Everything one IEKF iteration needs from ``P-`` and ``H_i``.

    Built by :meth:`StructuredCovariance.gain`; ``step`` gives ``P- H^T S^-1 v``.
    """

    def __init__(
        self, covariance: StructuredCovariance, linearisation: Linearisation, noise: np.ndarray
    ) -> None:
        self._covariance = covariance
        self._h_g = linearisation.bias_plane_jacobian
        self._point_jacobian = linearisation.point_jacobian
        self._h_p: scipy.sparse.csr_matrix | None = None
        if self._point_jacobian is None:
            self._local = np.empty(0, dtype=np.int64)
        else:
            self._local = self._point_jacobian.points()
        #: ``D``: the local points' prior variances, the point part of ``B``.
        self._local_variance = covariance.point_variance[self._local]

        innovation = self._h_g @ covariance.base_bias_plane @ self._h_g.T + noise_matrix(noise)
        if self._point_jacobian is not None:
            innovation += self._point_jacobian.weighted_gram(self._local, self._local_variance)
        self._cross = []  # W_k = H V_k^T, (rows, rows_k)
        coupled = [self._local]
        dim = covariance.dim
        for downdate in covariance.downdates:
            cross = self._h_g @ downdate.factor[:, :dim].T
            if downdate.points is None:
                if self._local.size:
                    raise RuntimeError("a grasp's point covariance was not kept but is needed")
            else:
                coupled.append(downdate.points)
                common, in_local, in_downdate = np.intersect1d(
                    self._local, downdate.points, assume_unique=True, return_indices=True
                )
                if common.size:
                    block = downdate.factor[:, dim + columns3(in_downdate)]
                    cross = cross + self._point_columns()[:, columns3(in_local)] @ block.T
            innovation -= cross @ cross.T
            self._cross.append(cross)
        self._cholesky = scipy.linalg.cho_factor(innovation, lower=True)
        #: Sorted indices of every point the gain can move: this A and earlier grasps' A.
        self.points = union(*coupled)

    def _point_columns(self) -> scipy.sparse.csr_matrix:
        """``H_p`` over the local points (3B, 3U), built on first use (several grasps only)."""
        if self._h_p is None:
            self._h_p = self._point_jacobian.sparse(self._local)
        return self._h_p

    def _scatter(self, target: np.ndarray, points: np.ndarray, values: np.ndarray) -> None:
        """Add values laid out over ``points`` into ``target`` laid out over ``self.points``."""
        target[..., columns3(np.searchsorted(self.points, points))] += values

    def _pairs(self):
        return zip(self._covariance.downdates, self._cross, strict=True)

    def step(self, innovation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``P- H^T S^-1 v`` split into its (b, m) part and its point part.

        Returns:
            ``(G,)`` increment of ``g``, the sorted indices of the points it moves and their
            ``(U, 3)`` increments (metres).
        """
        alpha = scipy.linalg.cho_solve(self._cholesky, innovation)
        delta_g = self._covariance.base_bias_plane @ (self._h_g.T @ alpha)
        delta_p = np.zeros(3 * len(self.points))
        if self._point_jacobian is not None:
            moved = self._point_jacobian.transpose_times(self._local, alpha)
            self._scatter(delta_p, self._local, (self._local_variance[:, None] * moved).ravel())
        dim = self._covariance.dim
        for downdate, cross in self._pairs():
            coefficients = cross.T @ alpha
            delta_g -= downdate.factor[:, :dim].T @ coefficients
            if downdate.points is not None:
                values = downdate.factor[:, dim:].T @ coefficients
                self._scatter(delta_p, downdate.points, -values)
        return delta_g, self.points, delta_p.reshape(-1, 3)

    def _whitened_bias_plane(self) -> np.ndarray:
        """``L^-1 (H P-)[:, g]``, (rows, G)."""
        product = self._h_g @ self._covariance.base_bias_plane
        for downdate, cross in self._pairs():
            product -= cross @ downdate.factor[:, : self._covariance.dim]
        return scipy.linalg.solve_triangular(self._cholesky[0], product, lower=True)

    def bias_plane_posterior(self) -> np.ndarray:
        """The (G, G) block of ``(I - K H) P-``."""
        whitened = self._whitened_bias_plane()
        return self._covariance.bias_plane() - whitened.T @ whitened

    def downdate(self, with_points: bool) -> _Downdate:
        """``V = L^-1 H P-`` over (b, m) and, if asked (or free), over ``self.points``."""
        if self.points.size == 0:
            return _Downdate(self._whitened_bias_plane(), self.points)
        if not with_points:
            return _Downdate(self._whitened_bias_plane(), None)
        if any(d.points is None for d in self._covariance.downdates):
            raise RuntimeError("a grasp's point covariance was not kept but is needed")
        dim = self._covariance.dim
        product = np.zeros((len(self._h_g), dim + 3 * len(self.points)))
        product[:, :dim] = self._h_g @ self._covariance.base_bias_plane
        point_part = product[:, dim:]
        if self._local.size:
            variance = np.repeat(self._local_variance, 3)
            self._scatter(point_part, self._local, self._point_columns().toarray() * variance)
        for downdate, cross in self._pairs():
            product[:, :dim] -= cross @ downdate.factor[:, :dim]
            self._scatter(point_part, downdate.points, -cross @ downdate.factor[:, dim:])
        factor = scipy.linalg.solve_triangular(self._cholesky[0], product, lower=True)
        return _Downdate(factor, self.points)


class StructuredCovariance:
    """Covariance of ``(g, p_1 .. p_N)`` as block-diagonal prior minus low-rank downdates.

    Args:
        bias_plane: ``(G, G)`` prior covariance of ``g`` (its size sets the state's).
        point_variance: ``(N,)`` isotropic prior variance of each point (m^2).
    """

    def __init__(self, bias_plane: np.ndarray, point_variance: np.ndarray) -> None:
        self.base_bias_plane = np.array(bias_plane, dtype=float)
        #: The length ``G`` of ``g``.
        self.dim = len(self.base_bias_plane)
        self.point_variance = np.asarray(point_variance, dtype=float)
        self.downdates: list[_Downdate] = []

    def bias_plane(self) -> np.ndarray:
        """The current (G, G) covariance of ``g``."""
        result = self.base_bias_plane.copy()
        for downdate in self.downdates:
            block = downdate.factor[:, : self.dim]
            result -= block.T @ block
        return result

    def add_bias_plane_noise(self, noise: np.ndarray) -> None:
        """``P <- P + Q`` with ``Q`` acting on ``g`` only."""
        self.base_bias_plane = self.base_bias_plane + noise

    def gain(self, linearisation: Linearisation, noise: np.ndarray) -> StructuredGain:
        """Prepare ``S = H P H^T + R`` (Cholesky) for one iteration."""
        return StructuredGain(self, linearisation, noise)

    def commit(self, gain: StructuredGain, with_points: bool) -> None:
        """``P <- (I - K H) P`` with the gain of the last iteration.

        ``with_points=False`` keeps only the (b, m) columns of the downdate, which is all a
        caller needs after the last grasp of Stage 2; a later gain over points then raises.
        """
        self.downdates.append(gain.downdate(with_points))

    def dense(self) -> np.ndarray:
        """The full ``(G + 3N)^2`` matrix (small problems and tests only)."""
        size = self.dim + 3 * len(self.point_variance)
        result = np.zeros((size, size))
        result[: self.dim, : self.dim] = self.base_bias_plane
        diagonal = np.arange(self.dim, size)
        result[diagonal, diagonal] = np.repeat(self.point_variance, 3)
        for downdate in self.downdates:
            if downdate.points is None:
                raise RuntimeError("a grasp's point covariance was not kept")
            columns = np.concatenate([np.arange(self.dim), self.dim + columns3(downdate.points)])
            result[np.ix_(columns, columns)] -= downdate.factor.T @ downdate.factor
        return result
