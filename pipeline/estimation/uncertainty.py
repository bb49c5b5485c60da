"""What the estimate does not know yet, and how much a grasp would teach it (docs/method.md §11).

The hidden side of the completed model is the mirror image ``q_n = f_mb(p_n)`` of every
cloud point. Its position uncertainty comes from the plane and the bias (the state ``g``,
covariance ``P``) and from the point's own camera noise, which is the same on the visible
side and which no grasp can remove far from its contacts. The quantities here measure the
part that comes from ``g``, in metres, with the linearisation ``q_n ~ J_n g``
(``J_n = d f_mb / d g`` at ``p_n``, :func:`~.geometry.side_jacobian`):

    hidden-side std   sqrt(mean_n tr(J_n P J_n^T)) = sqrt(tr(P M)),  M = mean_n J_n^T J_n

the RMS over the hidden side of each point's positional std (all three axes), of which the
plane's block of ``P`` and ``M`` alone gives the hidden side's std against the visible side
(the shape, which re-grasping does not unsettle); and

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

**What a grasp teaches about the model where it holds the object.** The estimate after a
grasp places the whole completed model where the object stands in that grasp: the visible
side moved by the bias (``J_n = d f_b / d g``, no plane columns), the hidden side by the
bias and the plane. :func:`model_gram` averages ``J_n^T J_n`` over both sides, so
``tr(P M_m)`` is the model's mean squared positional std and ``tr((P - P+) M_m)`` what a
grasp teaches about the model it leaves behind, the shape and the object's place alike.
Every grasp that touches learns the bias across its pads' closing direction; only one that
presses on faces turned along the plane learns where along the plane the object sits,
which the prior and the re-grasp noise ``Q`` leave uncertain by about a centimetre.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from pipeline.estimation.correspondences import PointIndex, exclusive_sides, find_correspondences
from pipeline.estimation.geometry import PLANE, normal_derivatives, side_jacobian
from pipeline.estimation.iekf import GraspContacts
from pipeline.estimation.measurement import freeze, linearise


def hidden_side_gram(points_m: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``M = mean_n J_n^T J_n`` over the mirror images of ``points_m`` (``(N, 3)``, unbiased
    frame R) at the state ``g``: ``tr(P M)`` is the hidden side's mean squared positional
    std under a covariance ``P`` of ``g``. Shape (G, G), ``G = len(g)``."""
    jacobians = side_jacobian(np.asarray(points_m, dtype=float), g, pivot_m, back=True)
    return np.einsum("nki,nkj->ij", jacobians, jacobians) / len(jacobians)


def model_gram(points_m: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """``M_m = mean J_n^T J_n`` over the visible side (``points_m`` moved by the bias) and
    its mirror image together (``(N, 3)``, unbiased frame R) at the state ``g``:
    ``tr(P M_m)`` is the completed model's mean squared positional std under a covariance
    ``P`` of ``g``. Shape (G, G), ``G = len(g)``."""
    points = np.asarray(points_m, dtype=float)
    jacobians = np.concatenate(
        [side_jacobian(points, g, pivot_m, back=back) for back in (False, True)]
    )
    return np.einsum("nki,nkj->ij", jacobians, jacobians) / len(jacobians)


def hidden_side_std_m(covariance: np.ndarray, gram: np.ndarray) -> float:
    """RMS positional std of the hidden side (m) from the covariance of ``g`` and
    :func:`hidden_side_gram`."""
    return float(np.sqrt(max(np.trace(covariance @ gram), 0.0)))


def hidden_shape_std_m(covariance: np.ndarray, gram: np.ndarray) -> float:
    """RMS positional std (m) of the hidden side against the visible side, the completed
    model's shape: :func:`hidden_side_std_m` from the plane's block of the
    covariance of ``g`` alone, the bias moving both sides together (it rotates the plane's
    columns of ``J_n``, which leaves their gram unchanged). The re-grasp noise ``Q`` grows
    the bias only, so this is the part of the hidden side's uncertainty that more grasps
    reduce; the object's place, where the bias puts it, each re-grasp unsettles again."""
    plane = PLANE
    return float(np.sqrt(max(np.trace(covariance[plane, plane] @ gram[plane, plane]), 0.0)))


def plane_offset_std_m(covariance: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> float:
    """Std (m) of the symmetry plane's distance from ``pivot_m``, ``m_r - n . c``, from the
    covariance of ``g`` (six parameters, or seven with a leaning plane)."""
    gradient = np.zeros(len(g))
    gradient[4] = 1.0
    gradient[5:] = -(normal_derivatives(g) @ np.asarray(pivot_m, dtype=float))
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


def expected_gain_m2(
    covariance: np.ndarray, jacobian: np.ndarray, nuisance: np.ndarray, gram: np.ndarray
) -> float:
    """Expected reduction of ``tr(P M)`` (m^2), the mean squared positional std of the
    points ``gram`` was built over (:func:`hidden_side_gram`, :func:`model_gram`), by the
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
    for :func:`expected_gain_m2`, with ``R`` the noise the reported covariance counts
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
        return np.zeros((0, len(g))), np.zeros((0, 0))
    measurement = freeze(found, contacts.positions_m, contacts.noise)
    linearisation = linearise(measurement, g, points_m, pivot_m, with_points=True)
    points = linearisation.point_jacobian
    local = points.points()
    nuisance = points.weighted_gram(local, point_variance_m2[local])
    nuisance += contacts.reported_noise_matrix(measurement)
    return linearisation.bias_plane_jacobian, nuisance
