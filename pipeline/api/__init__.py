"""The public API for plugin authors: everything a stage implementation needs, in one import.

::

    from pipeline.api import TactileModel, Contacts, param, hookimpl

What is named here keeps its meaning across symfuse releases; the rest of ``pipeline`` is
the core's own business and may change. ``docs/plugins.md`` explains each contract, and
:mod:`pipeline.testing` has the helpers to test a plugin (an analytic world, a registry
with your plugin, a tiny scene, a ready estimation problem).

Conventions: SI units (metres, radians, seconds, newtons) everywhere; points and poses in
the robot frame ``R`` (z up, table top at ``z = table_height_m``) unless a name says
otherwise; camera frames follow OpenCV (x right, y down, z forward); transforms are 4x4
arrays named ``T_<to>_<from>``.

Building an estimator's result: an estimator returns an :class:`EstimateResult` of three
:class:`StageEstimate` s, Stage 0 (the initial state it was given), 1 (bias and plane
corrected) and 2 (points corrected too); :func:`stage_estimate` builds one from a plane, a
bias and the object points, completing the model (the points and their mirror image, both
moved by the bias) so that every estimator's output means the same.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import (
    EXIT_BAD_INPUT,
    EXIT_ESTIMATE_FAILED,
    EXIT_OK,
    EXIT_PLUGIN_RAISED,
    ConfigError,
    InputError,
    PluginError,
    StageFailure,
    SymfuseError,
)
from pipeline.hookspecs import hookimpl
from pipeline.io.open3d_loader import open3d
from pipeline.io.units import UNIT_SCALE, Units, check_distance, check_extent, scale_of
from pipeline.params import NoParams, check_ordered, param, project
from pipeline.perception.depth import backproject_depth, project_points
from pipeline.stages import (
    STAGES,
    Estimator,
    GraspPlanner,
    Segmenter,
    SensorSource,
    StageImplementation,
    SymmetryInitialiser,
    TactileModel,
    World,
)
from pipeline.types import (
    BIAS_PLANE_PARAMETERS,
    BendingFinger,
    Bias,
    CameraImage,
    CameraIntrinsics,
    ClosingPad,
    Consistency,
    Contacts,
    DepthObservation,
    EstimateResult,
    EstimateStatus,
    EstimationProblem,
    GraspCandidate,
    GraspOutcome,
    GraspPlan,
    GripperSpec,
    HandGeometry,
    Housing,
    IterationState,
    LiftOutcome,
    ObjectPose,
    PadLayout,
    PadMount,
    PlanStatus,
    PointCloud,
    SceneObject,
    SceneSetup,
    StageEstimate,
    SymmetryHypothesis,
    SymmetryInit,
    SymmetryPlane,
    TaxelState,
)

__all__ = [
    "BIAS_PLANE_PARAMETERS",
    "EXIT_BAD_INPUT",
    "EXIT_ESTIMATE_FAILED",
    "EXIT_OK",
    "EXIT_PLUGIN_RAISED",
    "STAGES",
    "UNIT_SCALE",
    "BendingFinger",
    "Bias",
    "CameraImage",
    "CameraIntrinsics",
    "ClosingPad",
    "ConfigError",
    "Consistency",
    "Contacts",
    "DepthObservation",
    "EstimateResult",
    "EstimateStatus",
    "EstimationProblem",
    "Estimator",
    "GraspCandidate",
    "GraspOutcome",
    "GraspPlan",
    "GraspPlanner",
    "GripperSpec",
    "HandGeometry",
    "Housing",
    "InputError",
    "IterationState",
    "LiftOutcome",
    "NoParams",
    "ObjectPose",
    "PadLayout",
    "PadMount",
    "PlanStatus",
    "PluginError",
    "PointCloud",
    "SceneObject",
    "SceneSetup",
    "Segmenter",
    "SensorSource",
    "StageEstimate",
    "StageFailure",
    "StageImplementation",
    "SymfuseError",
    "SymmetryHypothesis",
    "SymmetryInit",
    "SymmetryInitialiser",
    "SymmetryPlane",
    "TactileModel",
    "TaxelState",
    "Units",
    "World",
    "backproject_depth",
    "check_distance",
    "check_extent",
    "check_ordered",
    "cloud_points",
    "hookimpl",
    "open3d",
    "param",
    "project",
    "project_points",
    "scale_of",
    "stage_estimate",
]


def cloud_points(problem: EstimationProblem, estimator: str) -> np.ndarray:
    """The ``(N, 3)`` object points of ``problem`` (frame R, m).

    Raises:
        StageFailure: the cloud is empty (naming ``estimator``).
    """
    from pipeline.estimation.problem import checked_points

    return checked_points(problem, estimator)


def stage_estimate(
    stage: int,
    plane: SymmetryPlane,
    bias: Bias,
    points: np.ndarray,
    covariance: np.ndarray,
    status: EstimateStatus,
    iterations: int = 0,
    seconds: float = 0.0,
    active_points: int = 0,
) -> StageEstimate:
    # Nine parameters: a plugin's estimator reports every field of a stage in one call.
    """One stage of an estimate, with its completed model.

    Args:
        stage: 0 (the initial state), 1 (bias and plane corrected) or 2 (points too).
        plane: the estimated symmetry plane, frame R.
        bias: the estimated bias (the rigid planar motion between what the camera saw and
            where the hand found the object), about its own ``pivot_m``.
        points: ``(N, 3)`` the estimated object points as the camera saw them (unbiased),
            m; for Stages 0 and 1 the cloud's points.
        covariance: ``(6, 6)`` covariance of :data:`BIAS_PLANE_PARAMETERS`
            (``b_theta, b_x, b_y, b_z, m_r, m_theta``) in rad and m; NaN when not estimated.
        status: ``"initial"`` for Stage 0; ``"converged"``, ``"max_iterations"``,
            ``"no_correspondence"`` or ``"diverged"`` for a fused stage (a claim: only say
            ``converged`` when your iteration met its criterion).
        iterations: iterations the stage used (0 when nothing iterates).
        seconds: wall time the stage took.
        active_points: points that took part in the last update (0 when not applicable).

    Returns:
        A :class:`StageEstimate` whose ``completed`` is ``bias(points)`` followed by
        ``bias(plane.mirror(points))``.
    """
    from pipeline.estimation.problem import stage_estimate as from_state

    g = np.array([bias.yaw_rad, *bias.translation_m, plane.offset_m, plane.theta_rad])
    return from_state(
        stage,
        g,
        covariance,
        np.asarray(points, dtype=np.float64),
        bias.pivot_m,
        iterations,
        status,
        seconds,
        active_points,
    )
