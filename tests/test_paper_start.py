"""When the fusion from the searched start fails, it is fused again from Stage 0
(pipeline.estimation.paper_start)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from pipeline.estimation.consistency import ConsistencySettings
from pipeline.estimation.iekf import fuse
from pipeline.estimation.map_params import fusion_problem
from pipeline.estimation.paper_start import NAME, paper_start_stages
from pipeline.estimation.problem import estimate_result
from pipeline.experiments import ExperimentOptions, fig10
from pipeline.experiments.synthetic_study import make_estimator, run_trial
from pipeline.synthetic import make_case

SETTINGS = ConsistencySettings()


@pytest.fixture(scope="module")
def fused():
    """A parallel-jaw case fused from Stage 0 and diagnosed: the fusion, its outcomes and
    its stages."""
    case = make_case(np.random.default_rng(5), gripper="parallel")
    estimator = make_estimator("iekf", {"start_search": False})
    p = estimator.params
    window = (p.window_along_normal_m, p.window_across_normal_m)
    fusion = fusion_problem(case.problem, p, "iekf", window, p.facing_filter)
    outcomes = fuse(fusion, estimator.settings())
    stages = estimate_result(fusion, outcomes, 0.0, case.problem.view, SETTINGS).stages
    return case, fusion, outcomes, stages


class Refusals:
    """A stand-in for the estimator's re-fusion: records the problems it is given and
    returns ``outcomes``."""

    def __init__(self, outcomes):
        self.outcomes, self.problems = outcomes, []

    def __call__(self, problem):
        self.problems.append(problem)
        return self.outcomes


def _moved(outcomes, start):
    return (dataclasses.replace(outcomes[0], g_start=start), *outcomes[1:])


def test_a_failed_stage_from_a_searched_start_is_fused_again_from_stage_0(fused):
    case, fusion, outcomes, stages = fused
    assert all(stage.status in ("converged", "max_iterations") for stage in stages[1:])
    failed = [stages[0], dataclasses.replace(stages[1], status="diverged"), stages[2]]
    start = fusion.g_init + np.array([0.0, 0.02, 0.0, 0.0, 0.0, 0.0])
    refuse = Refusals(outcomes)
    tree = cKDTree(fusion.points_m)
    revised = paper_start_stages(
        fusion, failed, _moved(outcomes, start), refuse, case.problem.view, SETTINGS, tree
    )
    # Fused again once, from Stage 0; every stage of that fusion passes, so it replaces
    # both fused stages and says why.
    assert len(refuse.problems) == 1
    np.testing.assert_array_equal(refuse.problems[0].g_start, fusion.g_init)
    assert [stage.hypothesis.name for stage in revised[1:]] == [NAME, NAME]
    assert "diverged" in revised[1].hypothesis.replaced
    assert all(stage.consistency.consistent for stage in revised[1:])
    assert [stage.status for stage in revised[1:]] == [o.status for o in outcomes]


def test_nothing_is_fused_again_when_every_stage_holds_or_the_start_was_stage_0(fused):
    case, fusion, outcomes, stages = fused
    tree = cKDTree(fusion.points_m)
    moved = _moved(outcomes, fusion.g_init + 0.01)
    failed = [stages[0], dataclasses.replace(stages[1], status="inconsistent"), stages[2]]
    for given, outcome in ((stages, moved), (failed, outcomes), (failed, _moved(outcomes, None))):
        refuse = Refusals(outcomes)
        revised = paper_start_stages(
            fusion, given, outcome, refuse, case.problem.view, SETTINGS, tree
        )
        assert not refuse.problems
        assert revised == list(given)


def test_a_refusion_that_does_not_hold_leaves_the_fused_stages(fused):
    case, fusion, outcomes, stages = fused
    failed = [stages[0], dataclasses.replace(stages[1], status="diverged"), stages[2]]
    diverged = tuple(dataclasses.replace(o, status="diverged") for o in outcomes)
    revised = paper_start_stages(
        fusion,
        failed,
        _moved(outcomes, fusion.g_init + 0.01),
        Refusals(diverged),
        case.problem.view,
        SETTINGS,
        cKDTree(fusion.points_m),
    )
    assert [stage.status for stage in revised] == [stage.status for stage in failed]
    assert all(stage.hypothesis is None for stage in revised)


@pytest.mark.slow
def test_three_pads_whose_searched_start_diverges_end_right_from_stage_0():
    """A randomised fig10 case (three fingers, 40 mm bias) whose searched start lay on the
    wrong side of the object: Stage 1 diverged there, and Stage 2, run from Stage 0 with
    the points free, ended 4.6 mm off the diameter yet consistent. From Stage 0 both
    stages converge, right."""
    tasks = [
        task
        for task in fig10.tasks(ExperimentOptions(repeats=15, seed=0))
        if task.key == "three_finger/bias40/trial7"
    ]
    assert math.isclose(tasks[0].params["bias_mm"], 40.0)
    row = run_trial(tasks[0].params)
    assert row["stage1_hypothesis"] == row["stage2_hypothesis"] == NAME
    assert row["stage2_status"] in ("converged", "max_iterations")
    assert row["stage2_diameter_error_mm"] < 4.0
