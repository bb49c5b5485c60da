"""The ``icp`` estimator: one-point-per-taxel maximum-likelihood baseline."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

from pipeline import hookimpl
from pipeline.estimation.problem import estimate_result
from pipeline.params import param, project
from pipeline.types import EstimateResult, EstimationProblem

from .iekf import IekfEstimator


class IcpEstimator(IekfEstimator):
    """ICP baseline: each taxel matched to its nearest front/back point (paper sec. 5.1).

    Solves the same bias + plane (Stage 1) and point (Stage 2) MAP problem as ``iekf`` with
    :mod:`pipeline.estimation.icp`, sharing ``iekf``'s noise, prior and re-grasp parameters;
    the correspondence window, schedule and side options do not apply. ``active_points``
    counts the matched taxels.
    """

    name = "icp"

    @dataclass(frozen=True)
    class Params(IekfEstimator.Params):
        max_match_distance_m: float = param(
            0.02, "a taxel farther than this from every point has no match (m)", above=0.0
        )
        last_stage: Literal[1, 2] = param(2, "1: bias + plane only; 2: also the points")

    def estimate(self, problem: EstimationProblem) -> EstimateResult:
        from pipeline.estimation.icp import IcpSettings, icp_fuse  # scipy.optimize

        started = time.perf_counter()
        fusion = self.fusion_problem(problem)
        settings = project(IcpSettings, self.params)
        outcomes = icp_fuse(fusion, settings, last_stage=self.params.last_stage)
        return estimate_result(fusion, outcomes, started, problem.view, self.consistency_settings())


@hookimpl
def symfuse_register_stages(registry):
    registry.add(IcpEstimator)
