"""Gate candidates kept from one iteration of the filter to the next.

Within a pass of the filter the points stay put (Stage 1) and the gates move by a fraction
of their width from one iteration to the next, so searching the points near every gate
again would find the same ones. :class:`GateCandidates` keeps, per gate, every point within
:data:`CANDIDATE_REACH` of it and proves, for the next call's gates, that nothing outside
can be inside them; the exact gate test on the kept points then gives what a search would.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.estimation.aggregation import GATE_CHI2_3DOF_95

#: Whitened radius (gate units, the gate's own is sqrt(7.815) = 2.8) within which a gate's
#: candidates are kept for the next call.
CANDIDATE_REACH = float(np.sqrt(GATE_CHI2_3DOF_95)) + 1.0


@dataclass(frozen=True)
class GateCandidates:
    """The points within :data:`CANDIDATE_REACH` of some gates, kept for the next call
    that tests the same taxels against the same, unmoved points.

    A point outside the kept set was at whitened distance ``|y| >= reach`` from its old
    gate; in the new gate, with ``M = L_new^-1 L_old`` and ``delta`` the centre's motion
    whitened by the old gate, its distance is ``|M (y + delta)| >= sigma_min(M) (reach -
    |delta|)``. When that bound reaches the gate's ``sqrt(7.815)`` for every gate
    (:meth:`covers`), the kept set holds every point of the new gates.

    Attributes:
        centres: ``(T, 3)`` the gates' centres when the points were found.
        lower: ``(T, 3, 3)`` Cholesky factors of their covariances.
        counts: ``(T,)`` points kept per gate.
        point: ``(K,)`` the kept points' indices, gate by gate.
    """

    centres: np.ndarray
    lower: np.ndarray
    counts: np.ndarray
    point: np.ndarray

    def covers(self, centres: np.ndarray, inverse: np.ndarray) -> bool:
        """True when every point inside the gates of ``centres`` and inverse covariances
        ``inverse`` ((T, 3, 3)) is kept (see the class docstring)."""
        if len(centres) != len(self.centres):
            return False
        moved = np.linalg.solve(self.lower, (self.centres - centres)[:, :, None])[:, :, 0]
        reach = CANDIDATE_REACH - np.linalg.norm(moved, axis=1)
        stretch = np.einsum("tji,tjk,tkl->til", self.lower, inverse, self.lower)
        shortest = np.sqrt(np.maximum(np.linalg.eigvalsh(stretch)[:, 0], 0.0))
        # A relative margin of 1e-9 against the rounding of the bound itself.
        gate = np.sqrt(GATE_CHI2_3DOF_95) * (1.0 + 1e-9)
        return bool(np.all((reach > 0.0) & (shortest * reach >= gate)))
