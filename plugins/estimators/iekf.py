"""The ``iekf`` estimator: the paper's visuo-tactile iterated EKF."""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Literal

from pipeline.api import EstimateResult, EstimationProblem, Estimator, hookimpl, param, project
from pipeline.api.estimation import (
    MapParams,
    consistency_settings,
    estimate_result,
    fusion_problem,
    regrasp_noise,
)

if TYPE_CHECKING:  # the kernels (and scipy) load when an estimate runs, not with the plugins
    from pipeline.api.estimation import AfterViewSettings, IekfSettings
    from pipeline.api.planning import MeasurementModel


class IekfEstimator(Estimator):
    """Visuo-tactile IEKF fusing taxel contacts with the mirrored cloud (paper sec. 3-5).

    A thin adapter over :func:`pipeline.estimation.iekf.fuse` (structured covariance). The
    bias pivot is the centroid of the cloud, recorded in every stage's ``Bias``. It uses
    the problem's after-views (``after_view``): each grasp's is registered to the cloud
    and fused as a measurement of the bias before that grasp's taxels. Noise,
    priors and self-diagnosis are :class:`~pipeline.estimation.map_params.MapParams`, shared
    with ``icp``; defaults come from the hardware (docs/method.md §4).
    """

    name = "iekf"

    @dataclass(frozen=True)
    class Params(MapParams):
        window_along_normal_m: float = param(
            0.003, "C_t: how far a taxel 'sees' along its normal, std (m)", above=0.0
        )
        window_across_normal_m: float = param(
            0.0017, "C_t: std across the normal, half the 3.4 mm taxel pitch (m)", above=0.0
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
        start_search: bool = param(
            True,
            "Stage 1 starts at the best state of a coarse grid over the bias translation and "
            "the plane, scored by the taxels' distances to the model and the prior (the prior "
            "stays Stage 0's); False starts at Stage 0 as in the paper",
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
        after_view: bool = param(
            True,
            "fuse the camera's view after each grasp, when the problem has one, as a "
            "measurement of the object's motion (docs/after-view.md); False ignores it",
        )
        after_view_calibration_yaw_rad: float = param(
            0.02,
            "after-view: std of the camera calibration's yaw error, which both views share "
            "and the after-view cannot see (rad)",
            above=0.0,
        )
        after_view_calibration_xy_m: float = param(
            0.005,
            "after-view: std of each horizontal component of the camera calibration's "
            "translation error, which both views share (m)",
            above=0.0,
        )
        after_view_floor_yaw_rad: float = param(
            0.02,
            "after-view: std of the registration's yaw error beyond its own covariance (the "
            "object's tilt in the grasp, correlated depth noise) (rad)",
            at_least=0.0,
        )
        after_view_floor_xy_m: float = param(
            0.001,
            "after-view: std of each horizontal component of the registration's error beyond "
            "its own covariance (m)",
            at_least=0.0,
        )
        after_view_hand_calibration: bool = param(
            True,
            "after-view: measure the camera's calibration error on the hand seen holding the "
            "object, where its known pose puts it, instead of taking it as unknown; a "
            "direction the hand's view does not fix keeps the calibration prior "
            "(docs/after-view.md)",
        )
        after_view_hand_floor_yaw_rad: float = param(
            0.005,
            "after-view, hand calibration: std of its yaw error beyond its own covariance (rad)",
            at_least=0.0,
        )
        after_view_hand_floor_xy_m: float = param(
            0.0005,
            "after-view, hand calibration: std of each horizontal component of its error "
            "beyond its own covariance (the hand's model against its image) (m)",
            at_least=0.0,
        )
        after_view_gate_alpha: float = param(
            0.001,
            "after-view: false-alarm probability of the chi-square gate on its innovation; a "
            "registration beyond it is not fused",
            above=0.0,
            below=1.0,
        )

    def settings(self) -> IekfSettings:
        """The kernel's iteration control under these parameters."""
        from pipeline.api.estimation import IekfSettings

        return project(IekfSettings, self.params)

    def measurement_model(self) -> MeasurementModel:
        """``C_t``, ``R``, the point prior, the facing filter and the re-grasp noise of
        these parameters."""
        from pipeline.api.planning import MeasurementModel

        p = self.params
        return MeasurementModel(
            window_std_m=(p.window_along_normal_m, p.window_across_normal_m),
            noise_std_m=(p.noise_along_normal_m, p.noise_across_normal_m),
            point_std_m=p.point_std_m,
            facing_filter=p.facing_filter,
            regrasp_noise=regrasp_noise(p),
        )

    def after_view_settings(self) -> AfterViewSettings | None:
        """How the after-view enters the filter, None when ``after_view`` is off; the
        registration's noise is the cloud's (``point_std_m``)."""
        from pipeline.api.estimation import AfterViewSettings, RegistrationSettings

        p = self.params
        if not p.after_view:
            return None
        return AfterViewSettings(
            registration=RegistrationSettings(noise_std_m=p.point_std_m),
            calibration_yaw_rad=p.after_view_calibration_yaw_rad,
            calibration_xy_m=p.after_view_calibration_xy_m,
            floor_yaw_rad=p.after_view_floor_yaw_rad,
            floor_xy_m=p.after_view_floor_xy_m,
            hand_calibration=p.after_view_hand_calibration,
            hand_floor_yaw_rad=p.after_view_hand_floor_yaw_rad,
            hand_floor_xy_m=p.after_view_hand_floor_xy_m,
            gate_alpha=p.after_view_gate_alpha,
        )

    def estimate(self, problem: EstimationProblem) -> EstimateResult:
        started = time.perf_counter()  # Stage 0's setup includes loading the fusion
        from pipeline.api.estimation import fuse

        p = self.params
        window = (p.window_along_normal_m, p.window_across_normal_m)
        fusion = fusion_problem(
            problem, p, self.name, window, p.facing_filter, self.after_view_settings()
        )
        settings = self.settings()
        outcomes = fuse(fusion, settings, last_stage=p.last_stage)
        # The alternative hypotheses (docs/method.md §9) re-fuse under the same settings.
        refuse = partial(fuse, settings=settings, last_stage=p.last_stage)
        checks = consistency_settings(p)
        return estimate_result(fusion, outcomes, started, problem.view, checks, refuse)


@hookimpl
def symfuse_register_stages(registry):
    registry.add(IekfEstimator)
