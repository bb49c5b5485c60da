"""The ``mirror-only`` estimator: vision alone, no tactile fusion."""

from __future__ import annotations

import time
from dataclasses import dataclass

from pipeline.api import EstimateResult, EstimationProblem, Estimator, hookimpl, param
from pipeline.api.estimation import checked_points, diagonal_covariance, initial_state
from pipeline.api.estimation import stage_estimate_from_state as stage_estimate


class MirrorOnlyEstimator(Estimator):
    """Vision-only baseline: the initialiser's mirrored cloud, contacts ignored.

    This is the "before fusion" column of the paper's tables: it shows what symmetry alone
    achieves. Stages 1 and 2 repeat Stage 0 so that every estimator returns the same layout;
    they report status ``converged`` with 0 iterations because there is nothing to iterate.
    The reported covariance is the prior the IEKF would start from (its parameters below),
    which is the honest uncertainty of a model no contact has corrected. It ignores the
    problem's after-views too: vision alone means the first view alone.
    """

    name = "mirror-only"

    @dataclass(frozen=True)
    class Params:
        prior_b_theta_rad: float = param(0.05, "reported std of the bias yaw (rad)", above=0.0)
        prior_b_xyz_m: float = param(
            0.01, "reported std of each bias translation component (m)", above=0.0
        )
        prior_m_r_m: float = param(0.0325, "reported std of the plane offset m_r (m)", above=0.0)
        prior_m_theta_rad: float = param(
            0.17, "reported std of each angle of the plane normal (rad)", above=0.0
        )

    def estimate(self, problem: EstimationProblem) -> EstimateResult:
        started = time.perf_counter()
        p = self.params
        points = checked_points(problem, self.name)
        pivot = points.mean(axis=0)
        g = initial_state(problem, pivot)
        # A leaning plane (seven parameters) has its elevation's std the azimuth's.
        angles = (p.prior_m_theta_rad,) * (len(g) - 5)
        covariance = diagonal_covariance(
            (
                p.prior_b_theta_rad,
                p.prior_b_xyz_m,
                p.prior_b_xyz_m,
                p.prior_b_xyz_m,
                p.prior_m_r_m,
                *angles,
            )
        )
        seconds = time.perf_counter() - started
        stages = tuple(
            stage_estimate(
                stage,
                g,
                covariance,
                points,
                pivot,
                0,
                "initial" if stage == 0 else "converged",
                seconds if stage == 0 else 0.0,
                0,
            )
            for stage in range(3)
        )
        return EstimateResult(stages=stages)


@hookimpl
def symfuse_register_stages(registry):
    registry.add(MirrorOnlyEstimator)
