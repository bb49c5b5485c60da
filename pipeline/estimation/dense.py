"""Textbook dense IEKF covariance: the reference for tests and the benchmark baseline.

Holds the full ``(G + 3N)^2`` covariance ``P`` (``G`` the length of ``g``: 6, or 7 for a
plane of any orientation) and builds a dense ``H`` of shape ``(rows, G + 3N)``; the gain
is ``K = P H^T S^-1`` (``S`` solved with a Cholesky factorisation, never inverted) and the
update the textbook ``P+ = (I - K H) P-``. It plugs into the same iteration loop as
:class:`~pipeline.estimation.structured.StructuredCovariance` (see
:func:`pipeline.estimation.iekf.fuse`), so the two differ only in how the covariance is
stored and updated. Memory is ``8 (G + 3N)^2`` bytes: use it for N up to a few thousand.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from pipeline.estimation.measurement import Linearisation
from pipeline.estimation.structured import noise_matrix


class DenseGain:
    """``K = P- H^T S^-1`` of one iteration, formed explicitly."""

    def __init__(
        self, covariance: DenseCovariance, linearisation: Linearisation, noise: np.ndarray
    ) -> None:
        n_points, dim = covariance.n_points, covariance.dim
        rows = len(linearisation.bias_plane_jacobian)
        jacobian = np.zeros((rows, dim + 3 * n_points))
        jacobian[:, :dim] = linearisation.bias_plane_jacobian
        if linearisation.point_jacobian is not None:
            jacobian[:, dim:] = linearisation.point_jacobian.dense(n_points)
        prior = covariance.matrix
        innovation = jacobian @ prior @ jacobian.T + noise_matrix(noise)
        cholesky = scipy.linalg.cho_factor(innovation, lower=True)
        self.jacobian = jacobian
        self.gain = scipy.linalg.cho_solve(cholesky, jacobian @ prior).T
        self._covariance = covariance

    def step(self, innovation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``K v`` as ``(G,)`` increment of ``g``, point indices and ``(N, 3)`` increments."""
        delta = self.gain @ innovation
        points = np.arange(self._covariance.n_points)
        dim = self._covariance.dim
        return delta[:dim], points, delta[dim:].reshape(-1, 3)

    def posterior(self) -> np.ndarray:
        """``(I - K H) P-``."""
        prior = self._covariance.matrix
        return prior - self.gain @ (self.jacobian @ prior)

    def bias_plane_posterior(self) -> np.ndarray:
        """The (G, G) block of ``(I - K H) P-``."""
        prior, dim = self._covariance.matrix, self._covariance.dim
        correction = self.gain[:dim] @ (self.jacobian @ prior[:, :dim])
        return prior[:dim, :dim] - correction


class DenseCovariance:
    """The full covariance of ``(g, p_1 .. p_N)`` as one dense matrix.

    Args:
        bias_plane: ``(G, G)`` prior covariance of ``g`` (its size sets the state's).
        point_variance: ``(N,)`` isotropic prior variance of each point (m^2).
    """

    def __init__(self, bias_plane: np.ndarray, point_variance: np.ndarray) -> None:
        point_variance = np.asarray(point_variance, dtype=float)
        self.n_points = len(point_variance)
        self.dim = len(bias_plane)
        size = self.dim + 3 * self.n_points
        self.matrix = np.zeros((size, size))
        self.matrix[: self.dim, : self.dim] = bias_plane
        diagonal = np.arange(self.dim, size)
        self.matrix[diagonal, diagonal] = np.repeat(point_variance, 3)

    def bias_plane(self) -> np.ndarray:
        return self.matrix[: self.dim, : self.dim].copy()

    def add_bias_plane_noise(self, noise: np.ndarray) -> None:
        self.matrix[: self.dim, : self.dim] += noise

    def gain(self, linearisation: Linearisation, noise: np.ndarray) -> DenseGain:
        return DenseGain(self, linearisation, noise)

    def commit(self, gain: DenseGain, with_points: bool) -> None:
        """``P <- (I - K H) P`` (``with_points`` is irrelevant: everything is kept)."""
        self.matrix = gain.posterior()

    def dense(self) -> np.ndarray:
        return self.matrix.copy()
