"""The estimated symmetry plane for users of the model: in the robot frame and in the
object's own frame, with its covariance, and as the BOP toolkit's ``symmetries_discrete``
(docs/method.md §12).

The object frame is the frame of the model's mesh files: z up (the table's normal), x along
the plane's normal, origin on the plane and on the table below the model's centre. The
plane there is ``x = 0`` and the reflection about it the 4x4 ``diag(-1, 1, 1, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.metrics.fits import plane_after_bias
from pipeline.types import Bias, SymmetryPlane


def _direction(theta: float) -> np.ndarray:
    return np.array([np.cos(theta), np.sin(theta), 0.0])


def _turned(theta: float) -> np.ndarray:
    """The derivative of :func:`_direction` by ``theta``."""
    return np.array([-np.sin(theta), np.cos(theta), 0.0])


def plane_jacobian(plane: SymmetryPlane, bias: Bias) -> np.ndarray:
    """``(2, 6)`` derivative of the moved plane's ``(theta_rad, offset_m)``
    (:func:`pipeline.metrics.fits.plane_after_bias`) by the state
    ``(b_theta, b_x, b_y, b_z, m_r, m_theta)``.

    With ``theta' = m_theta + b_theta`` and ``r' = m_r - n(m_theta).c + n(theta').(c + t)``
    (``c`` the bias's pivot, ``t`` its translation, ``n(a) = (cos a, sin a, 0)``).
    """
    theta = plane.theta_rad + bias.yaw_rad
    moved, turned = _direction(theta), _turned(theta)
    reach = bias.pivot_m + bias.translation_m
    jacobian = np.zeros((2, 6))
    jacobian[0, 0] = jacobian[0, 5] = 1.0
    jacobian[1, 0] = turned @ reach
    jacobian[1, 1:4] = moved
    jacobian[1, 4] = 1.0
    jacobian[1, 5] = -_turned(plane.theta_rad) @ bias.pivot_m + turned @ reach
    return jacobian


def object_frame(plane: SymmetryPlane, centre_m: np.ndarray, table_z_m: float) -> np.ndarray:
    """``(4, 4)`` ``T_robot_object``: x along the plane's normal, z up, origin the point of
    the plane at height ``table_z_m`` nearest to ``centre_m`` (frame R)."""
    normal = plane.normal
    centre = np.asarray(centre_m, dtype=float).reshape(3)
    origin = centre - (centre @ normal - plane.offset_m) * normal
    origin[2] = table_z_m
    transform = np.eye(4)
    transform[:3, 0] = normal
    transform[:3, 1] = np.cross([0.0, 0.0, 1.0], normal)
    transform[:3, 2] = [0.0, 0.0, 1.0]
    transform[:3, 3] = origin
    return transform


def reflection(normal: np.ndarray, offset: float) -> np.ndarray:
    """``(4, 4)`` the mirror map ``p -> p - 2 (n.p - offset) n`` as a homogeneous transform."""
    normal = np.asarray(normal, dtype=float).reshape(3)
    transform = np.eye(4)
    transform[:3, :3] -= 2.0 * np.outer(normal, normal)
    transform[:3, 3] = 2.0 * offset * normal
    return transform


@dataclass(frozen=True)
class SymmetryExport:
    """The plane of one stage's completed model, as users of the model take it.

    Attributes:
        plane_robot: the plane in frame R (the one the completed model is symmetric about).
        covariance_robot: ``(2, 2)`` covariance of its ``(theta_rad, offset_m)``; None
            when the stage has no covariance (a Stage 0 without contacts).
        T_robot_object: ``(4, 4)`` the object frame (module docstring).
        covariance_object: ``(2, 2)`` covariance of the plane's angle about the object's z
            (from its x axis, rad) and its offset along x (m), both 0 at the estimate;
            None with ``covariance_robot``.
    """

    plane_robot: SymmetryPlane
    covariance_robot: np.ndarray | None
    T_robot_object: np.ndarray
    covariance_object: np.ndarray | None

    def to_json(self) -> dict:
        """``result.json``'s ``symmetry``; the BOP entry's translation is in mm, as BOP's
        models are (it is zero: the plane passes through the object frame's origin)."""
        return {
            "robot": {
                "normal": self.plane_robot.normal.tolist(),
                "offset_m": self.plane_robot.offset_m,
                "theta_rad": self.plane_robot.theta_rad,
                "covariance_theta_offset": _listed(self.covariance_robot),
                "reflection": reflection(
                    self.plane_robot.normal, self.plane_robot.offset_m
                ).tolist(),
            },
            "object": {
                "T_robot_object": self.T_robot_object.tolist(),
                "normal": [1.0, 0.0, 0.0],
                "offset_m": 0.0,
                "covariance_angle_offset": _listed(self.covariance_object),
            },
            "bop": {"symmetries_discrete": [reflection([1.0, 0.0, 0.0], 0.0).ravel().tolist()]},
        }


def _listed(matrix: np.ndarray | None) -> list | None:
    return None if matrix is None else matrix.tolist()


def export_symmetry(
    plane: SymmetryPlane,
    bias: Bias,
    covariance: np.ndarray | None,
    centre_m: np.ndarray,
    table_z_m: float,
) -> SymmetryExport:
    """The plane after ``bias`` with its covariance, in frame R and in the object frame.

    Args:
        plane, bias: a stage's estimate (the plane before the bias, as the estimator
            holds it).
        covariance: ``(6, 6)`` of ``(b_theta, b_x, b_y, b_z, m_r, m_theta)``; None, or
            not finite: unknown.
        centre_m: the model's centre (frame R): the object frame's origin lies below it,
            on the plane.
        table_z_m: the table's height in frame R.
    """
    moved = plane_after_bias(plane, bias)
    transform = object_frame(moved, centre_m, table_z_m)
    covariance = None if covariance is None else np.asarray(covariance, dtype=float)
    if covariance is None or covariance.shape != (6, 6) or not np.isfinite(covariance).all():
        return SymmetryExport(moved, None, transform, None)
    jacobian = plane_jacobian(plane, bias)
    covariance_robot = jacobian @ covariance @ jacobian.T
    # Turning the plane by d_theta about R's origin moves it, at the object frame's origin
    # o, by -n'(theta).o along its normal: the offset there changes by d_r - (n'.o) d_theta.
    to_object = np.array([[1.0, 0.0], [-_turned(moved.theta_rad) @ transform[:3, 3], 1.0]])
    return SymmetryExport(
        plane_robot=moved,
        covariance_robot=covariance_robot,
        T_robot_object=transform,
        covariance_object=to_object @ covariance_robot @ to_object.T,
    )
