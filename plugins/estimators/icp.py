"""The ``icp`` estimator: one-point-per-taxel maximum-likelihood baseline."""

from __future__ import annotations

import time
from dataclasses import dataclass

from pipeline.api import EstimateResult, EstimationProblem, Estimator, hookimpl, param, project
from pipeline.api.estimation import MapParams, consistency_settings, estimate_result, fusion_problem


class IcpEstimator(Estimator):
    """ICP baseline: each taxel matched to its nearest front/back point (paper sec. 5.1).

    Solves the same bias + plane (Stage 1) and point (Stage 2) MAP problem as ``iekf`` with
    :mod:`pipeline.estimation.icp`, under the same noise, priors, re-grasp noise and
    self-diagnosis (:class:`~pipeline.estimation.map_params.MapParams`); a taxel's match is
    its nearest point, so there is no correspondence window. ``active_points`` counts the
    matched taxels. It ignores the problem's after-views: the baseline is the paper's.
    """

    name = "icp"

    @dataclass(frozen=True)
    class Params(MapParams):
        max_match_distance_m: float = param(
            0.02, "a taxel farther than this from every point has no match (m)", above=0.0
        )
        max_iterations: int = param(
            30,
            "re-matching rounds per grasp and stage; the solve stops earlier when the matches "
            "stop changing",
            at_least=1,
        )

    def estimate(self, problem: EstimationProblem) -> EstimateResult:
        from pipeline.api.estimation import IcpSettings, icp_fuse

        p = self.params
        started = time.perf_counter()
        # The window and the taxel normals only weigh the IEKF's correspondences; nearest
        # neighbours need neither.
        noise = (p.noise_along_normal_m, p.noise_across_normal_m)
        fusion = fusion_problem(problem, p, self.name, noise, facing_filter=False)
        outcomes = icp_fuse(fusion, project(IcpSettings, p), last_stage=p.last_stage)
        return estimate_result(fusion, outcomes, started, problem.view, consistency_settings(p))


@hookimpl
def symfuse_register_stages(registry):
    registry.add(IcpEstimator)
