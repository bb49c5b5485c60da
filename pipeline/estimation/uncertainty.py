"""What the estimate does not know yet, and how much a grasp would teach it (docs/method.md §11).

The hidden side of the completed model is the mirror image ``q_n = f_mb(p_n)`` of every
cloud point. Its position uncertainty comes from the plane and the bias (the state ``g``,
covariance ``P``) and from the point's own camera noise, which is the same on the visible
side and which no grasp can remove far from its contacts. The quantities here measure the
part that comes from ``g``, in metres, with the linearisation ``q_n ~ J_n g``
(``J_n = d f_mb / d g`` at ``p_n``, :func:`~.geometry.side_jacobian`):

    hidden-side std   sqrt(mean_n tr(J_n P J_n^T)) = sqrt(tr(P M)),  M = mean_n J_n^T J_n

the RMS over the hidden side of each point's positional std (all three axes); and

    plane offset std  sqrt(j^T P j),  j = d(m_r - n(m_theta) . c) / d g

the std of the plane's distance from the bias pivot ``c`` (the object), since ``m_r`` itself
is measured from the robot origin.

**What a grasp teaches.** A grasp's taxels are a measurement ``y = H_g g + H_p p + v`` (the
estimator's own linearisation, paper eqs. 10-12, with ``v ~ N(0, R)``). In that
linear-Gaussian model the posterior covariance does not depend on the value ``y`` takes, so
the *expected* posterior covariance of ``g`` is the EKF update

    P+ = P - P H_g^T S^-1 H_g P,   S = H_g P H_g^T + H_p D H_p^T + R

with the points as a nuisance (``D`` their covariance, marginalised into ``S``), and the
expected reduction of the hidden side's mean squared uncertainty is

    gain = tr((P - P+) M)  (m^2),

the drop of the squared hidden-side std above. It weighs the plane and bias by how far
they move the hidden surface: a plane angle error matters in proportion to the object's
length along the plane, a bias error everywhere.

**What a grasp teaches about the shape.** The bias only moves the object: it carries the
visible and the hidden side alike, and the object is released and moved again before the
next grasp, which adds the re-grasp noise ``Q`` back. Ranking grasps by ``M`` therefore
ranks them mostly by how well each pins the bias it will forget, the same for every grasp
that touches: ``tr(Q M)`` is tens of mm^2 against the plane's few. The shape, the hidden
side relative to the visible side, depends on the plane alone, so :func:`shape_gram`
keeps only the plane's columns of ``J_n`` (``M_s``), and ``tr((P - P+) M_s)`` is what a
grasp teaches about the object's hidden side wherever the object stands. The bias stays in
``P`` and ``P+`` as a nuisance: a grasp that cannot tell the plane from the bias teaches
the shape little.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .correspondences import PointIndex, exclusive_sides, find_correspondences
from .geometry import BIAS_PLANE_DIM, PLANE, side_jacobian
from .iekf import GraspContacts
from .measurement import freeze, linearise


def hidden_side_gram(points_m: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``M = mean_n J_n^T J_n`` over the mirror images of ``points_m`` (``(N, 3)``, unbiased
    frame R) at the state ``g``: ``tr(P M)`` is the hidden side's mean squared positional
    std under a covariance ``P`` of ``g``. Shape (6, 6)."""
    jacobians = side_jacobian(np.asarray(points_m, dtype=float), g, pivot_m, back=True)
    return np.einsum("nki,nkj->ij", jacobians, jacobians) / len(jacobians)


def shape_gram(points_m: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """:func:`hidden_side_gram` restricted to the plane: ``tr(P M_s)`` is the hidden side's
    mean squared positional std relative to the visible side (its shape), which the bias
    does not change. Shape (6, 6), zero outside the plane's block."""
    gram = np.zeros((BIAS_PLANE_DIM, BIAS_PLANE_DIM))
    gram[PLANE, PLANE] = hidden_side_gram(points_m, g, pivot_m)[PLANE, PLANE]
    return gram


def hidden_side_std_m(covariance: np.ndarray, gram: np.ndarray) -> float:
    """RMS positional std of the hidden side (m) from the ``(6, 6)`` covariance of ``g`` and
    :func:`hidden_side_gram`."""
    return float(np.sqrt(max(np.trace(covariance @ gram), 0.0)))


def plane_offset_std_m(covariance: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> float:
    """Std (m) of the symmetry plane's distance from ``pivot_m``, ``m_r - n(m_theta) . c``,
    from the ``(6, 6)`` covariance of ``g``."""
    theta = float(g[5])
    gradient = np.zeros(BIAS_PLANE_DIM)
    gradient[4] = 1.0
    gradient[5] = -float(np.array([-np.sin(theta), np.cos(theta)]) @ np.asarray(pivot_m)[:2])
    return float(np.sqrt(max(gradient @ covariance @ gradient, 0.0)))


def expected_posterior(
    covariance: np.ndarray, jacobian: np.ndarray, nuisance: np.ndarray
) -> np.ndarray:
    """The EKF posterior covariance of ``g`` after a measurement with ``H_g = jacobian``
    (``(m, 6)``) whose noise, with the points' part folded in, is ``nuisance``
    (``H_p D H_p^T + R``, ``(m, m)``): ``P - P H^T S^-1 H P``, ``S = H P H^T + nuisance``."""
    cross = jacobian @ covariance
    innovation = cross @ jacobian.T + nuisance
    factor = scipy.linalg.cho_factor(innovation, lower=True)
    posterior = covariance - cross.T @ scipy.linalg.cho_solve(factor, cross)
    return (posterior + posterior.T) / 2.0


def hidden_side_gain_m2(
    covariance: np.ndarray, jacobian: np.ndarray, nuisance: np.ndarray, gram: np.ndarray
) -> float:
    """Expected reduction of the hidden side's mean squared positional std (m^2) by the
    measurement of :func:`expected_posterior`: ``tr((P - P+) M)``, never negative."""
    if len(jacobian) == 0:
        return 0.0
    posterior = expected_posterior(covariance, jacobian, nuisance)
    return max(float(np.trace((covariance - posterior) @ gram)), 0.0)


def predicted_measurement(
    index: PointIndex,
    points_m: np.ndarray,
    g: np.ndarray,
    pivot_m: np.ndarray,
    contacts: GraspContacts,
    covariance: np.ndarray,
    point_variance_m2: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The linearised measurement the IEKF would make of ``contacts`` at the state
    ``(g, points_m)``: its correspondences (eq. 9, gates from ``covariance``, one side per
    taxel), frozen weights and Jacobian (paper eqs. 10-12), as ``(H_g, H_p D H_p^T + R)``
    for :func:`hidden_side_gain_m2`, with ``R`` the noise the reported covariance counts
    the taxels with (``contacts.reported_noise_matrix``), as the filter will after the grasp. No
    taxel with a correspondence gives an empty ``H_g`` (``(0, 6)``): the grasp would teach
    nothing.

    Args:
        index: KD-tree over ``points_m``.
        point_variance_m2: ``(N,)`` isotropic variance of each point (``D``).
    """
    found = find_correspondences(
        index,
        points_m,
        g,
        pivot_m,
        contacts.positions_m,
        contacts.window,
        covariance,
        alternative=False,
        need_pairs=True,
        taxel_normals=contacts.normals,
        facing_g=g,
    )
    found = exclusive_sides(found)
    if not found.supported_taxels().any():
        return np.zeros((0, BIAS_PLANE_DIM)), np.zeros((0, 0))
    measurement = freeze(found, contacts.positions_m, contacts.noise)
    linearisation = linearise(measurement, g, points_m, pivot_m, with_points=True)
    points = linearisation.point_jacobian
    local = points.points()
    nuisance = points.weighted_gram(local, point_variance_m2[local])
    nuisance += contacts.reported_noise_matrix(measurement)
    return linearisation.bias_plane_jacobian, nuisance
