"""Measurement and correspondence covariances (docs/method.md §4, paper sec. 5.2).

Every covariance here is a robot-frame (3, 3) matrix in square metres.
"""

from __future__ import annotations

import numpy as np


def unit_normals(normals: np.ndarray) -> np.ndarray:
    """``(M, 3)`` normals scaled to unit length."""
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def normal_ellipsoids(
    normals: np.ndarray, sigma_along_m: float, sigma_across_m: float
) -> np.ndarray:
    """``s_n^2 nu nu^T + s_t^2 (I - nu nu^T)`` for each unit normal ``nu``, shape (M, 3, 3).

    With ``sigma_along_m < sigma_across_m`` this is the flattened measurement noise ``R``;
    with ``sigma_along_m > sigma_across_m`` the elongated correspondence window ``C_t``.
    """
    unit = unit_normals(normals)
    outer = unit[:, :, None] * unit[:, None, :]
    return sigma_along_m**2 * outer + sigma_across_m**2 * (np.eye(3)[None] - outer)


#: The std across a taxel's normal (m) with which the covariance a stage reports counts a
#: taxel: so large that the taxel tells nothing there. The residual across the normal
#: compares the taxel with the weighted mean of the points near it, and on a flat side that
#: mean slides along with the object; with the weights frozen (paper eq. 12) the filter
#: counts it as a measurement of where the object sits along the side (docs/method.md §4).
NO_INFORMATION_M = 1.0


def shared_pad_noise(pad_errors_m: np.ndarray, pads: np.ndarray) -> np.ndarray:
    """The ``(3B, 3B)`` covariance of errors that all blocks of one pad share: block
    ``(i, j)`` is ``u_i u_j^T`` when blocks ``i`` and ``j`` lie on the same pad, else zero.

    Args:
        pad_errors_m: ``(B, 3)`` each block's shared error as a vector ``u_i`` (m): its std
            along the taxel normal times the normal.
        pads: ``(B,)`` the pad of each block.
    """
    errors = np.asarray(pad_errors_m, dtype=float)
    pads = np.asarray(pads)
    same = (pads[:, None] == pads[None, :]).astype(float)
    count = len(errors)
    blocks = same[:, None, :, None] * errors[:, :, None, None] * errors[None, None, :, :]
    return blocks.reshape(3 * count, 3 * count)


def correspondence_covariances(
    window: np.ndarray, jacobians: np.ndarray, state_covariance: np.ndarray
) -> np.ndarray:
    """``C_i = C_t,i + J_i P J_i^T`` (paper eq. 14), shape (M, 3, 3).

    Args:
        window: ``C_t`` per taxel, (M, 3, 3).
        jacobians: ``d f / d g`` of the side's map at the taxel, (M, 3, 6).
        state_covariance: the (6, 6) covariance of ``g``; for the front ``f_b`` has zero
            plane columns, so only the bias block contributes, as the paper prescribes.
    """
    propagated = np.einsum("mij,jk,mlk->mil", jacobians, state_covariance, jacobians)
    return window + propagated
