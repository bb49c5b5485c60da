"""Parameters shared by the estimators that solve the paper's MAP problem over the bias, the
plane and the points (``iekf`` and ``icp``), and the kernel inputs built from them.

Both weigh the same taxel noise ``R`` against the same priors and re-grasp noise ``Q`` and
diagnose their stages the same way; they differ in how taxels find their points (the IEKF's
correspondence window and weights, ICP's nearest neighbour), which each estimator's own
parameters add to :class:`MapParams`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

import numpy as np

from pipeline.estimation.geometry import BIAS_PLANE_DIM
from pipeline.estimation.problem import (
    bias_plane_covariance,
    checked_points,
    diagonal_covariance,
    grasp_contacts,
    initial_state,
    plane_angle_stds,
)
from pipeline.params import param
from pipeline.types import EstimationProblem

if TYPE_CHECKING:  # the kernels (and scipy) load when an estimate runs, not with the plugins
    from pipeline.estimation.after_view_term import AfterViewSettings
    from pipeline.estimation.consistency import ConsistencySettings
    from pipeline.estimation.iekf import FusionProblem


@dataclass(frozen=True)
class MapParams:
    """Noise, priors and self-diagnosis of the MAP estimators (defaults from the hardware:
    3.4 mm taxel pitch, a 65 mm PG-70 aperture, Kinect noise of about 2 mm at 1 m)."""

    noise_along_normal_m: float = param(
        0.001, "R: std along the taxel normal (pad surface position, compliance) (m)", above=0.0
    )
    noise_across_normal_m: float = param(
        0.003, "R: std within the pad plane (about one taxel pitch) (m)", above=0.0
    )
    prior_b_theta_rad: float = param(
        0.05,
        "prior std of the bias yaw: calibration plus object rotation in the grasp (rad)",
        above=0.0,
    )
    prior_b_xy_m: float = param(
        0.01,
        "prior std of each horizontal bias translation component: camera calibration plus "
        "the object sliding on the table as the jaws close (m)",
        above=0.0,
    )
    prior_b_z_m: float = param(
        0.002,
        "prior std of the vertical bias translation: the object stands on the table, which "
        "a top grasp neither lifts it from nor pushes it into, so only the depth "
        "calibration and the table-plane fit (about 1-2 mm) remain; side contacts on "
        "vertical faces barely observe b_z, so a wide prior lets it drift (m)",
        above=0.0,
    )
    prior_m_r_m: float = param(
        0.0325,
        "prior std of the plane's distance from the pivot (the cloud centroid), "
        "independent of m_theta: half the 65 mm gripper aperture (m)",
        above=0.0,
    )
    prior_m_theta_rad: float = param(
        0.4,
        "prior std of the plane normal angle m_theta: the initialiser's orientation error "
        "(VC hypotheses, or PCA axes of a nearly round cloud, can be off by tens of "
        "degrees; 23 deg puts a 45 deg error at 2 std, inside the 95 % gate) (rad)",
        above=0.0,
    )
    prior_m_lean_rad: float = param(
        0.05,
        "prior std of a leaning plane's normal: the angle it may turn in any direction on "
        "the sphere of normals (the azimuth-elevation chart's stds follow from it). A top "
        "grasp's pads on a lying object touch near the plane, where its tilt has no lever, "
        "so the camera's plane must hold it (docs/method.md §1) (rad)",
        above=0.0,
    )
    point_std_m: float = param(0.002, "prior std of each cloud point (sensor noise) (m)", above=0.0)
    regrasp_b_theta_rad: float = param(
        0.02, "Q: std of the yaw the object gains when re-grasped (rad)", at_least=0.0
    )
    regrasp_b_xy_m: float = param(
        0.005,
        "Q: std of each horizontal translation component gained when re-grasped: the "
        "release and the next grasp slide the object on the table (m)",
        at_least=0.0,
    )
    regrasp_b_z_m: float = param(
        0.0005,
        "Q: std of the vertical translation gained when re-grasped: the object stays on the "
        "table, and the vertical calibration error does not change between grasps; side "
        "contacts barely observe b_z, so a wide Q lets a later grasp lift the model (m)",
        at_least=0.0,
    )
    divergence_sigmas: float = param(
        10.0, "diverged when b or m leave this many prior stds around Stage 0", above=0.0
    )
    last_stage: Literal[1, 2] = param(
        2, "1: bias + plane only (result holds stages 0, 1); 2: also the points"
    )
    consistency_alpha: float = param(
        0.001,
        "self-diagnosis: false-alarm probability of each consistency test (taxel NIS "
        "against chi-square, model points in the camera's free space against the depth "
        "noise); a stage failing one is 'inconsistent'",
        above=0.0,
        below=1.0,
    )
    free_space_fraction: float = param(
        0.02,
        "self-diagnosis: largest share of the model's points allowed in space the camera "
        "saw empty (beyond the depth noise), for the completion near the silhouette",
        at_least=0.0,
        below=1.0,
    )


def fusion_problem(
    problem: EstimationProblem,
    params: MapParams,
    estimator: str,
    window_std_m: tuple[float, float],
    facing_filter: bool,
    after_view: AfterViewSettings | None = None,
) -> FusionProblem:
    """The kernels' view of ``problem`` under ``params``: the pivot is the cloud's
    centroid; each grasp's taxels carry the correspondence window ``C_t`` of
    ``window_std_m`` (along, across the normal; m) and, with ``facing_filter``, their
    normals; with ``after_view``, each grasp's after-view (when the problem has one and
    it registers) as a measurement of the bias. Raises
    :class:`~pipeline.errors.StageFailure` (naming ``estimator``) on an empty cloud."""
    from pipeline.estimation.iekf import FusionProblem

    p = params
    points = checked_points(problem, estimator)
    pivot = points.mean(axis=0)
    noise = (p.noise_along_normal_m, p.noise_across_normal_m)
    xy = p.prior_b_xy_m
    g_init = initial_state(problem, pivot)
    angles = plane_angle_stds(p.prior_m_theta_rad, p.prior_m_lean_rad, g_init)
    stds = (p.prior_b_theta_rad, xy, xy, p.prior_b_z_m, p.prior_m_r_m, *angles)
    grasps = [grasp_contacts(c, window_std_m, noise, facing_filter) for c in problem.grasps]
    if after_view is not None:
        from pipeline.estimation.after_view_term import after_view_measurement

        for k, contacts in enumerate(grasps):
            view = problem.after_view(k)
            if view is not None:
                measured = after_view_measurement(view, points, pivot, after_view)
                grasps[k] = replace(contacts, after_view=measured)
    return FusionProblem(
        points_m=points,
        pivot_m=pivot,
        g_init=g_init,
        covariance_init=bias_plane_covariance(stds, g_init, pivot),
        point_variance_m2=np.full(len(points), p.point_std_m**2),
        grasps=tuple(grasps),
        regrasp_noise=regrasp_noise(p, len(g_init)),
    )


def regrasp_noise(params: MapParams, state_dim: int = BIAS_PLANE_DIM) -> np.ndarray:
    """``Q``, the covariance over ``g`` (``state_dim`` parameters: six, or seven with a
    leaning plane) the object's motion adds before every grasp after the first: the bias'
    yaw and translation, not the plane."""
    p = params
    q_xy, q_z = p.regrasp_b_xy_m, p.regrasp_b_z_m
    plane = (0.0,) * (state_dim - 4)
    return diagonal_covariance((p.regrasp_b_theta_rad, q_xy, q_xy, q_z, *plane))


def consistency_settings(params: MapParams) -> ConsistencySettings:
    """The self-diagnosis thresholds: the model surface is as uncertain as one point."""
    from pipeline.estimation.consistency import ConsistencySettings

    return ConsistencySettings(
        alpha=params.consistency_alpha,
        surface_std_m=params.point_std_m,
        free_space_fraction=params.free_space_fraction,
    )
