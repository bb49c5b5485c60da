"""The ``iekf`` estimator: the paper's visuo-tactile iterated EKF."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from pipeline import hookimpl
from pipeline.estimation.problem import (
    bias_plane_covariance,
    checked_points,
    diagonal_covariance,
    estimate_result,
    grasp_contacts,
    initial_state,
)
from pipeline.params import param, project
from pipeline.stages import Estimator
from pipeline.types import EstimateResult, EstimationProblem

if TYPE_CHECKING:  # the kernels (and scipy) load when an estimate runs, not with the plugins
    from pipeline.estimation.consistency import ConsistencySettings
    from pipeline.estimation.iekf import FusionProblem, IekfSettings


class IekfEstimator(Estimator):
    """Visuo-tactile IEKF fusing taxel contacts with the mirrored cloud (paper sec. 3-5).

    A thin adapter over :func:`pipeline.estimation.iekf.fuse` (structured covariance). The
    bias pivot is the centroid of the cloud, recorded in every stage's ``Bias``. Defaults come
    from the hardware (docs/method.md §4): 3.4 mm taxel pitch, a 65 mm PG-70
    aperture, Kinect noise of about 2 mm at 1 m.
    """

    name = "iekf"

    @dataclass(frozen=True)
    class Params:
        noise_along_normal_m: float = param(
            0.001, "R: std along the taxel normal (pad surface position, compliance) (m)", above=0.0
        )
        noise_across_normal_m: float = param(
            0.003, "R: std within the pad plane (about one taxel pitch) (m)", above=0.0
        )
        window_along_normal_m: float = param(
            0.003, "C_t: how far a taxel 'sees' along its normal, std (m)", above=0.0
        )
        window_across_normal_m: float = param(
            0.0017, "C_t: std across the normal, half the 3.4 mm taxel pitch (m)", above=0.0
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
        point_std_m: float = param(
            0.002, "prior std of each cloud point (sensor noise) (m)", above=0.0
        )
        regrasp_b_theta_rad: float = param(
            0.02, "Q: std of the yaw the object gains when re-grasped (rad)", at_least=0.0
        )
        regrasp_b_xyz_m: float = param(
            0.005, "Q: std of each translation component gained when re-grasped (m)", at_least=0.0
        )
        schedule: Literal["standard", "alternative", "hybrid"] = param(
            "hybrid", "correspondence weights: eq. 9, eq. 13, or eq. 13 then eq. 9"
        )
        exclusive_sides: bool = param(
            True, "explain each taxel by its better-supported side only (False: both, eq. 11)"
        )
        facing_filter: bool = param(
            True,
            "a taxel only weighs cloud points whose surface normal has an elevation within "
            "about 45 deg of its own (a side pad cannot touch the top face) and, on the front, "
            "a horizontal direction within about 45 deg after the bias yaw; False: eq. 9 as "
            "in the paper",
        )
        refine_gates: bool = param(
            True,
            "Stage 1 iterates each grasp again with gates narrowed to its first pass's "
            "posterior (False: prior gates only)",
        )
        gate_tolerance_m: float = param(
            1e-3,
            "convergence of Stage 1's first pass (prior gates) when refine_gates is on: it only "
            "narrows the gates and starts the second pass, which converges to tolerance_m (m)",
            above=0.0,
        )
        max_iterations: int = param(30, "IEKF iteration cap per grasp, stage and pass", at_least=1)
        tolerance_m: float = param(
            1e-4,
            "convergence: largest motion of any completed-model point (front or mirrored) "
            "between iterations, well under the ~2 mm sensor noise (m)",
            above=0.0,
        )
        max_step_m: float = param(
            0.02,
            "trust region: largest motion of any completed-model point in one iteration; "
            "longer Gauss-Newton steps are shortened (m)",
            above=0.0,
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

    def fusion_problem(self, problem: EstimationProblem) -> FusionProblem:
        """The kernel's view of ``problem`` under these parameters."""
        from pipeline.estimation.iekf import FusionProblem

        p = self.params
        points = checked_points(problem, self.name)
        pivot = points.mean(axis=0)
        window = (p.window_along_normal_m, p.window_across_normal_m)
        noise = (p.noise_along_normal_m, p.noise_across_normal_m)
        xy, q_xyz = p.prior_b_xy_m, p.regrasp_b_xyz_m
        g_init = initial_state(problem, pivot)
        stds = (p.prior_b_theta_rad, xy, xy, p.prior_b_z_m, p.prior_m_r_m, p.prior_m_theta_rad)
        return FusionProblem(
            points_m=points,
            pivot_m=pivot,
            g_init=g_init,
            covariance_init=bias_plane_covariance(stds, g_init[5], pivot),
            point_variance_m2=np.full(len(points), p.point_std_m**2),
            grasps=tuple(grasp_contacts(c, window, noise, p.facing_filter) for c in problem.grasps),
            regrasp_noise=diagonal_covariance((p.regrasp_b_theta_rad, q_xyz, q_xyz, q_xyz, 0, 0)),
        )

    def consistency_settings(self) -> ConsistencySettings:
        """The self-diagnosis thresholds: the model surface is as uncertain as one point."""
        from pipeline.estimation.consistency import ConsistencySettings

        p = self.params
        return ConsistencySettings(
            alpha=p.consistency_alpha,
            surface_std_m=p.point_std_m,
            free_space_fraction=p.free_space_fraction,
        )

    def settings(self) -> IekfSettings:
        """The kernel's iteration control under these parameters."""
        from pipeline.estimation.iekf import IekfSettings

        return project(IekfSettings, self.params)

    def estimate(self, problem: EstimationProblem) -> EstimateResult:
        from pipeline.estimation.iekf import fuse

        started = time.perf_counter()
        fusion = self.fusion_problem(problem)
        outcomes = fuse(fusion, self.settings(), last_stage=self.params.last_stage)
        return estimate_result(fusion, outcomes, started, problem.view, self.consistency_settings())


@hookimpl
def symfuse_register_stages(registry):
    registry.add(IekfEstimator)
