"""The after-view as a measurement of the bias in the IEKF update (docs/after-view.md).

The camera looks again while the hand holds the object. Registering the after-view's visible
object points to the first view's cloud (:func:`~.registration.register_planar`, about the
bias' pivot) gives the planar motion ``D = (yaw, x, y)`` the object made between the views,
as the camera sees it. The bias ``b`` the taxels are compared under is the motion from the
first view's cloud to the object in the hand's (true) frame, ``f_b = E^-1 D``, with ``E`` the
camera-to-robot calibration error both views share, so

    y = E^-1 D = (b_theta, b_x, b_y) + n,

``n`` from the registration's own error and ``E``'s, carried through the composition
(:func:`compose`). The registration's error is its Gauss-Newton covariance (the sensor's
noise over the points the hand leaves visible) plus a floor (``floor_*``) for what that
covariance does not count: the object's tilt in the grasp, which a planar motion cannot
follow, the points' correlated noise and the hand's edge. ``E``'s prior is zero with std
``calibration_*``: by itself the after-view measures the object's motion, not where the
camera put it. With ``hand_calibration`` (the default) the hand measures ``E``: the points
the after-view sees on the hand, registered to the hand's surface where its known pose puts
it (with that prior), give ``E`` as the object's points give ``D``. The hand's thin fingers
need a registration that stays honest where they show the camera little
(:func:`hand_error`): a direction of ``E`` the hand's view does not fix keeps its prior.

The measurement is linear in ``g``, so fusing it before a grasp's taxels is the same as
fusing both at once; an innovation beyond the chi-square gate is an outlier (a wrong
registration) and is not fused. The calibration error is in the prior of ``b`` as well, and
it is the same in every view; counting it as noise independent of the prior (as here)
shrinks the measured motion a little toward the prior and, with several grasps, counts it
once per view (docs/method.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import gammaincinv

from pipeline.estimation.measurement import Linearisation
from pipeline.estimation.registration import RegistrationSettings, register_planar
from pipeline.types import AfterView

#: Rows of ``g`` the after-view measures: the bias' yaw and horizontal translation.
MEASURED = np.array([0, 1, 2])


@dataclass(frozen=True)
class AfterViewSettings:
    """How the after-view enters the filter.

    Attributes:
        registration: the registration's control (its noise is the sensor's).
        calibration_yaw_rad, calibration_xy_m: std of the calibration error's yaw and of
            each horizontal component of its translation: the part of the bias the
            after-view cannot see (without ``hand_calibration``).
        floor_yaw_rad, floor_xy_m: std of the registration's error beyond its own
            covariance, in yaw and in each horizontal component (rad, m).
        hand_calibration: measure the calibration error on the hand (see above).
        hand_floor_yaw_rad, hand_floor_xy_m: std of that measurement's error beyond its own
            covariance (the hand's model against its image, points by its edge).
        hand_gate_m: the hand's registration starts pairing points this near (m): the
            calibration error's reach, narrower than the object's (whose gate also spans
            the grasp's motion), so a finger cannot pair with its neighbour.
        hand_normal_cos: a hand point pairs only with a surface point whose normal
            agrees this well with its own (:class:`RegistrationSettings`).
        hand_min_leverage_points: a direction of the calibration error the hand's points
            fix with less information than this many points at full leverage keeps its
            prior (:class:`RegistrationSettings`).
        gate_alpha: false-alarm probability of the innovation's chi-square gate (3 dof).
    """

    registration: RegistrationSettings = field(default_factory=RegistrationSettings)
    calibration_yaw_rad: float = 0.02
    calibration_xy_m: float = 0.005
    floor_yaw_rad: float = 0.02
    floor_xy_m: float = 0.001
    hand_calibration: bool = True
    hand_floor_yaw_rad: float = 0.005
    hand_floor_xy_m: float = 0.0005
    hand_gate_m: float = 0.006
    hand_normal_cos: float = 0.7
    hand_min_leverage_points: float = 4.0
    gate_alpha: float = 0.001


@dataclass(frozen=True)
class AfterViewMeasurement:
    """One grasp's after-view as a linear measurement of ``g``.

    Attributes:
        motion: ``(3,)`` the measured ``(b_theta, b_x, b_y)`` (rad, m), about the bias pivot.
        noise: ``(3, 3)`` its covariance: the registration's plus the calibration's.
        gate: the largest squared Mahalanobis innovation fused.
        inliers: after-view points the registration used.
    """

    motion: np.ndarray
    noise: np.ndarray
    gate: float
    inliers: int

    def jacobian(self, state_dim: int) -> np.ndarray:
        """``(3, state_dim)``: the rows of ``g`` measured."""
        return np.eye(state_dim)[MEASURED]


def compose(
    motion: np.ndarray, calibration: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``E^-1 D`` of two planar motions ``(yaw, x, y)`` about the same pivot, and its
    ``(3, 3)`` Jacobians over ``D`` and over ``E``.

    ``D(p) = R_d (p - c) + c + t_d`` and ``E(p) = R_e (p - c) + c + t_e`` give
    ``E^-1 D (p) = R_e^T R_d (p - c) + c + R_e^T (t_d - t_e)``.
    """
    yaw_e = float(calibration[0])
    c, s = np.cos(yaw_e), np.sin(yaw_e)
    turn_back = np.array([[c, s], [-s, c]])
    gap = motion[1:3] - calibration[1:3]
    composed = np.array([motion[0] - yaw_e, *(turn_back @ gap)])
    by_motion = np.zeros((3, 3))
    by_motion[0, 0] = 1.0
    by_motion[1:, 1:] = turn_back
    by_calibration = np.zeros((3, 3))
    by_calibration[0, 0] = -1.0
    by_calibration[1:, 0] = np.array([[-s, c], [-c, -s]]) @ gap
    by_calibration[1:, 1:] = -turn_back
    return composed, by_motion, by_calibration


def after_view_measurement(
    view: AfterView, points_m: np.ndarray, pivot_m: np.ndarray, settings: AfterViewSettings
) -> AfterViewMeasurement | None:
    """The measurement of one after-view against the first view's ``points_m`` about
    ``pivot_m``; None when the object's registration finds too few points or does not
    converge."""
    moved = register_planar(view.points, points_m, pivot_m, settings.registration)
    if moved is None or not moved.converged:
        return None
    xy = settings.calibration_xy_m**2
    calibration = np.diag([settings.calibration_yaw_rad**2, xy, xy])
    floor = np.diag([settings.floor_yaw_rad**2, settings.floor_xy_m**2, settings.floor_xy_m**2])
    error, error_covariance = np.zeros(3), calibration
    if settings.hand_calibration:
        error, error_covariance = hand_error(view, pivot_m, settings, calibration)
    motion, by_motion, by_error = compose(moved.motion, error)
    noise = by_motion @ (moved.covariance + floor) @ by_motion.T
    noise += by_error @ error_covariance @ by_error.T
    return AfterViewMeasurement(
        motion=motion,
        noise=noise,
        gate=float(2.0 * gammaincinv(1.5, 1.0 - settings.gate_alpha)),
        inliers=moved.inliers,
    )


def hand_error(
    view: AfterView, pivot_m: np.ndarray, settings: AfterViewSettings, calibration: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The calibration error ``E`` and its covariance from the hand's points, under the
    prior ``calibration``; the prior itself when the registration fails.

    The registration starts within the calibration error's reach (``hand_gate_m``), pairs
    a seen point only with hand surface whose normal agrees with its own
    (``hand_normal_cos``: a finger's face by its edge must not pair with the face around
    the corner), and leaves to the prior every direction the points fix with less than
    ``hand_min_leverage_points`` points' information (a PG-70 seen head-on fixes ``E``
    along the line of sight through thousands of points, across it through a few grazing
    edge pixels).
    """
    # Only the hand's faces turned to the camera can be seen (the far side would pair with
    # the near side's points through a thin finger).
    camera_m = np.asarray(view.observation.T_robot_camera)[:3, 3]
    seen = np.einsum("ij,ij->i", view.hand_normals, camera_m - view.hand_surface) > 0.0
    control = replace(
        settings.registration,
        start_gate_m=settings.hand_gate_m,
        min_normal_cos=settings.hand_normal_cos,
        min_leverage_points=settings.hand_min_leverage_points,
    )
    hand = register_planar(
        view.hand_points,
        view.hand_surface[seen],
        pivot_m,
        control,
        view.hand_normals[seen],
        prior_covariance=calibration,
    )
    if hand is None or not hand.converged:
        return np.zeros(3), calibration
    xy = settings.hand_floor_xy_m**2
    return hand.motion, hand.covariance + np.diag([settings.hand_floor_yaw_rad**2, xy, xy])


def innovation(measurement: AfterViewMeasurement, g: np.ndarray) -> np.ndarray:
    """``y - H g``, the yaw difference wrapped to ``(-pi, pi]``."""
    difference = measurement.motion - g[MEASURED]
    difference[0] = (difference[0] + np.pi) % (2.0 * np.pi) - np.pi
    return difference


def linearisation(measurement: AfterViewMeasurement, g: np.ndarray) -> Linearisation:
    """The measurement in the form the covariance models take (no point columns)."""
    return Linearisation(
        prediction=g[MEASURED].copy(),
        bias_plane_jacobian=measurement.jacobian(len(g)),
        point_jacobian=None,
    )


def passes_gate(measurement: AfterViewMeasurement, g: np.ndarray, covariance: np.ndarray) -> bool:
    """Whether the innovation at ``g`` with the covariance of ``g`` is inside the
    chi-square gate."""
    h = measurement.jacobian(len(g))
    v = innovation(measurement, g)
    s = h @ covariance @ h.T + measurement.noise
    return bool(v @ np.linalg.solve(s, v) <= measurement.gate)
