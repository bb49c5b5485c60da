"""Bias, mirroring and their analytic Jacobians (docs/method.md §1).

All functions are pure and work on robot-frame arrays in metres and radians.

The bias-and-plane parameters are packed in one vector ``g``. The paper's six, for a
vertical plane, in the order of :data:`pipeline.types.BIAS_PLANE_PARAMETERS`:
``(b_theta, b_x, b_y, b_z, m_r, m_theta)``; a plane of any orientation adds its normal's
elevation, ``(b_theta, b_x, b_y, b_z, m_r, m_theta, m_phi)``
(:data:`pipeline.types.GENERAL_PLANE_PARAMETERS`). Every function here takes either: the
length of ``g`` says which.

* Bias: ``f_b(p) = R_z(b_theta) (p - c) + c + (b_x, b_y, b_z)`` with a fixed pivot ``c``.
* Mirror: ``f_m(p) = p - 2 (n.p - m_r) n`` with the unit normal
  ``n = (cos m_phi cos m_theta, cos m_phi sin m_theta, sin m_phi)``, ``m_phi = 0`` (a
  horizontal normal) in the paper's state (``m_theta`` is the *normal's* azimuth, as in
  :class:`pipeline.types.SymmetryPlane`).
* Mirror then bias: ``f_mb(p) = f_b(f_m(p))``.

The azimuth and elevation are a chart of the sphere of normals whose poles are the vertical
normals (a level mirror plane): there ``m_theta`` stops moving the normal. The planes an
object shows the camera from above and that the paper's state cannot hold lean at most
tens of degrees from vertical, far from those poles (docs/symmetry.md).

Both maps are isometries, so distances between a point and a taxel are the same before and
after inverting them; the correspondence search relies on that.
"""

from __future__ import annotations

import numpy as np

from pipeline.geometry.poses import rotation_z

#: Length of the paper's bias-and-plane state (a vertical plane).
BIAS_PLANE_DIM = 6
#: Length of the state with a plane of any orientation.
GENERAL_PLANE_DIM = 7
#: Slices into ``g``: the bias, and the plane (two or three parameters).
BIAS = slice(0, 4)
PLANE = slice(4, None)


def rotation_z_derivative(theta_rad: float) -> np.ndarray:
    """``d R_z / d theta``, (3, 3)."""
    c, s = np.cos(theta_rad), np.sin(theta_rad)
    return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 0.0]])


def plane_normal(m_theta_rad: float) -> np.ndarray:
    """Unit normal ``(cos m_theta, sin m_theta, 0)`` of the symmetry plane."""
    return np.array([np.cos(m_theta_rad), np.sin(m_theta_rad), 0.0])


def plane_tangent(m_theta_rad: float) -> np.ndarray:
    """``dn/dm_theta = (-sin m_theta, cos m_theta, 0)``: the plane's horizontal direction."""
    return np.array([-np.sin(m_theta_rad), np.cos(m_theta_rad), 0.0])


def state_normal(g: np.ndarray) -> np.ndarray:
    """The mirror plane's unit normal of the state ``g`` (six or seven parameters)."""
    if len(g) == BIAS_PLANE_DIM:
        return plane_normal(g[5])
    azimuth, elevation = g[5], g[6]
    return np.array(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ]
    )


def normal_derivatives(g: np.ndarray) -> np.ndarray:
    """``dn / d(m_theta[, m_phi])`` of :func:`state_normal`, one row per angle, (1 or 2, 3)."""
    if len(g) == BIAS_PLANE_DIM:
        return plane_tangent(g[5])[None, :]
    azimuth, elevation = g[5], g[6]
    c_az, s_az, c_el, s_el = np.cos(azimuth), np.sin(azimuth), np.cos(elevation), np.sin(elevation)
    return np.array([[-c_el * s_az, c_el * c_az, 0.0], [-s_el * c_az, -s_el * s_az, c_el]])


def normal_reflection(normal: np.ndarray) -> np.ndarray:
    """Linear part ``I - 2 n n^T`` of the mirroring across a plane with unit normal ``n``."""
    return np.eye(3) - 2.0 * np.outer(normal, normal)


def apply_bias(points: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``f_b`` applied to ``(N, 3)`` points."""
    rotation = rotation_z(g[0])
    return (points - pivot_m) @ rotation.T + pivot_m + g[1:4]


def mirror(points: np.ndarray, g: np.ndarray) -> np.ndarray:
    """``f_m`` applied to ``(N, 3)`` points (uses ``g[4:] = (m_r, m_theta[, m_phi])``)."""
    n = state_normal(g)
    return points - 2.0 * (points @ n - g[4])[:, None] * n[None, :]


def apply_mirror_bias(points: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``f_mb = f_b o f_m`` applied to ``(N, 3)`` points."""
    return apply_bias(mirror(points, g), g, pivot_m)


def completed_model(points: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """The completed model: ``f_b(p)`` of the ``(N, 3)`` points, then ``f_mb(p)``, (2N, 3).

    Both maps are affine, ``f_b(p) = R p + c + t - R c`` and ``f_mb(p) = R (I - 2 n n^T) p +
    2 m_r R n + c + t - R c``, so each half is one product and one sum written in place
    (:func:`apply_bias` and :func:`apply_mirror_bias` make a dozen passes over the points
    between them: a quarter of a second per stage at a million points).
    """
    rotation = rotation_z(g[0])
    offset = pivot_m + g[1:4] - rotation @ pivot_m
    count = len(points)
    completed = np.empty((2 * count, 3))
    front, back = completed[:count], completed[count:]
    np.matmul(points, rotation.T, out=front)
    front += offset
    normal = state_normal(g)
    np.matmul(points, (rotation @ normal_reflection(normal)).T, out=back)
    back += offset + 2.0 * g[4] * (rotation @ normal)
    return completed


def apply_side(points: np.ndarray, g: np.ndarray, pivot_m: np.ndarray, back: bool) -> np.ndarray:
    """``f_mb`` when ``back`` else ``f_b``."""
    return apply_mirror_bias(points, g, pivot_m) if back else apply_bias(points, g, pivot_m)


def invert_bias(points: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``f_b^-1``: the unbiased points that ``f_b`` maps onto ``points``."""
    rotation = rotation_z(g[0])
    return (points - pivot_m - g[1:4]) @ rotation + pivot_m


def invert_side(points: np.ndarray, g: np.ndarray, pivot_m: np.ndarray, back: bool) -> np.ndarray:
    """Pre-image under ``f_mb`` (the mirroring is its own inverse) or ``f_b``."""
    unbiased = invert_bias(points, g, pivot_m)
    return mirror(unbiased, g) if back else unbiased


def side_linear_part(g: np.ndarray, back: bool) -> np.ndarray:
    """``d f / d p`` (constant in ``p``): ``R_z`` for the front, ``R_z (I - 2 n n^T)`` back."""
    rotation = rotation_z(g[0])
    return rotation @ normal_reflection(state_normal(g)) if back else rotation


def bias_jacobian(points: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``d f_b(q) / d b`` at the points ``q``, shape (N, 3, 4), columns ``(b_theta, b_xyz)``."""
    jacobian = np.zeros((len(points), 3, 4))
    jacobian[:, :, 0] = (points - pivot_m) @ rotation_z_derivative(g[0]).T
    jacobian[:, :, 1:4] = np.eye(3)
    return jacobian


def mirror_plane_jacobian(points: np.ndarray, g: np.ndarray) -> np.ndarray:
    """``d f_m(p) / d (m_r, m_theta[, m_phi])``, shape (N, 3, 2 or 3).

    ``df_m/dm_r = 2 n`` and, for each angle ``a`` with ``n' = dn/da``
    (:func:`normal_derivatives`), ``df_m/da = -2 ((n'.p) n + (n.p - m_r) n')``.
    """
    n = state_normal(g)
    derivatives = normal_derivatives(g)
    jacobian = np.empty((len(points), 3, 1 + len(derivatives)))
    jacobian[:, :, 0] = 2.0 * n
    height = points @ n - g[4]
    for column, n_prime in enumerate(derivatives, start=1):
        jacobian[:, :, column] = -2.0 * (
            (points @ n_prime)[:, None] * n[None, :] + height[:, None] * n_prime[None, :]
        )
    return jacobian


def side_jacobian(points: np.ndarray, g: np.ndarray, pivot_m: np.ndarray, back: bool) -> np.ndarray:
    """``d f / d g`` of ``f_b`` (front) or ``f_mb`` (back) at the points, shape
    (N, 3, len(g)).

    The front does not depend on the plane, so its plane columns are zero.
    """
    jacobian = np.zeros((len(points), 3, len(g)))
    if back:
        mirrored = mirror(points, g)
        jacobian[:, :, BIAS] = bias_jacobian(mirrored, g, pivot_m)
        jacobian[:, :, PLANE] = np.einsum(
            "ij,njk->nik", rotation_z(g[0]), mirror_plane_jacobian(points, g)
        )
    else:
        jacobian[:, :, BIAS] = bias_jacobian(points, g, pivot_m)
    return jacobian


def box_corners(lower_m: np.ndarray, upper_m: np.ndarray) -> np.ndarray:
    """The 8 corners of the axis-aligned box ``[lower, upper]``, shape (8, 3)."""
    pick = (np.arange(8)[:, None] >> np.arange(3)[None, :]) & 1
    return np.where(pick == 1, upper_m, lower_m)


def image_step_bound(
    vertices_m: np.ndarray,
    g_old: np.ndarray,
    g_new: np.ndarray,
    pivot_m: np.ndarray,
    margin_m: float = 0.0,
) -> float:
    """Largest distance (m) any point moves, front (``f_b``) or mirrored (``f_mb``), when
    ``g`` changes from ``g_old`` to ``g_new``, over every point within ``margin_m`` of the
    convex hull of ``vertices_m``.

    For a fixed pair of states ``f(p; g_new) - f(p; g_old) = D p + e`` is affine in ``p``,
    so its norm is convex and its maximum over a convex polytope is reached at a vertex; a
    point ``q = p + d`` with ``|d| <= margin_m`` moves at most ``||D||_2 margin_m`` more. It
    turns angular steps into metres through the real lever arm (about the pivot for
    ``b_theta``, about the plane for its angles).
    """
    bounds = []
    for back in (False, True):
        moved = apply_side(vertices_m, g_new, pivot_m, back) - apply_side(
            vertices_m, g_old, pivot_m, back
        )
        linear_change = side_linear_part(g_new, back) - side_linear_part(g_old, back)
        bounds.append(
            float(np.max(np.linalg.norm(moved, axis=1)))
            + margin_m * float(np.linalg.norm(linear_change, ord=2))
        )
    return max(bounds)


def rebase_bias_translation(
    yaw_rad: float, translation_m: np.ndarray, old_pivot_m: np.ndarray, new_pivot_m: np.ndarray
) -> np.ndarray:
    """Translation that gives the same rigid motion when rotating about ``new_pivot_m``.

    ``R (p - c0) + c0 + t0 = R (p - c) + c + t`` for all ``p`` when
    ``t = t0 + (R - I)(c - c0)``.
    """
    offset = np.asarray(new_pivot_m, float) - np.asarray(old_pivot_m, float)
    return np.asarray(translation_m, float) + (rotation_z(yaw_rad) - np.eye(3)) @ offset
