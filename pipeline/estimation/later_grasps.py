"""A later grasp whose contacts contradict the model the earlier grasps built only locates
the object (docs/method.md §11).

With several grasps the estimator fuses them all, in order, each with its own bias. A later
grasp can pull the plane and the points where the evidence does not follow: its contacts
may meet a part the mirror image cannot complete (a handle, a nozzle), or the object may
have turned or tipped during the grasp beyond what the re-grasp noise ``Q`` allows, so that
wrong correspondences reshape the model. Then the fused model contradicts the camera or the
taxels although the model of the grasps before it did not.

The alternative here is the *earlier shape*: the estimate the grasps before the last gave
(the stage selected among them, with any alternative it took; computed the same way, so
recursively), located by the last grasp alone. The last grasp's bias is fused with the
plane held and the points fixed (Stage 1 on that grasp, from the earlier state and its
covariance plus ``Q``), so it says where the object now stands but not what it looks like.
The filter's location is not taken on trust. Where the contacts meet a part the mirror
image completes wrongly (a spray bottle's trigger head), the located bias can fit the last
grasp's taxels worse than the object standing where the earlier estimate left it: pressing
on one spot, the pads pin the object only along their closing direction, and the misfit
drags it along the rest (a yaw about the object's centre that the head barely feels). So
the bias is taken at the fraction of the filter's step (:data:`LOCATING_STEPS`, from 1, the
filter's bias, to 0, not moved) whose model the taxels fit best (lowest pad-averaged NIS),
as the hypotheses of :mod:`.hypotheses` take the best-fitting bounded step.

A pad on a part the mirror image does not complete (a mug's handle) drags that location
towards it, or leads the locating filter astray. When the earlier shape fails, and exactly
one pad of a last grasp of three or more explains the failure (without it, the earlier
shape where the earlier grasps left it fits the taxels), the other pads locate it
(``hypothesis.name`` ``"earlier shape without <pad>"``, as :mod:`.outlier_pads` leaves a
pad out of a single grasp), and it is judged on all the taxels.

The alternative replaces an inconsistent last stage when it passes every test of the
self-diagnosis on all the grasps and the camera. It also replaces it, keeping the status
``inconsistent``, when the last grasp's taxels contradict it but the camera accepts it and
it contradicts the taxels no more than any stage the camera accepts: it is then the stage
the selection (:func:`.consistency.select_stage`) takes. The flag stands, and the estimate
kept is the one the evidence supports best. Without it the selection fell back to Stage 0,
which throws away every earlier grasp as well as the last and contradicts the taxels more.
This holds only for an earlier estimate consistent with the grasps before: one already at
odds with them can fit the last grasp better than Stage 0 does by a location far from the
object. Its covariance carries the plane's uncertainty from the earlier estimate
(:func:`.hypotheses.unheld_covariance`). Every test is on the evidence, never on ground
truth.

No motion test (:func:`.hypotheses.moved_free_space`) applies: the object was released and
grasped again since the camera saw it, so its motion since then is real.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from pipeline.errors import estimate_failed
from pipeline.estimation.consistency import ConsistencySettings, assess
from pipeline.estimation.hypotheses import (
    HYPOTHESES,
    Refuse,
    held_problem,
    shortened_covariance,
    unheld_covariance,
)
from pipeline.estimation.iekf import FusionProblem, StageOutcome
from pipeline.estimation.outlier_pads import sole_explaining_pad, without_pad
from pipeline.estimation.problem import stage_estimate
from pipeline.types import Consistency, DepthObservation, Hypothesis, StageEstimate

#: The name the alternative's stages carry (``result.json``'s ``hypothesis``).
EARLIER_SHAPE = "earlier shape"
#: The components of ``g`` the last grasp does not move: the plane, as ``held-plane`` holds it.
_PLANE = HYPOTHESES["held-plane"]
#: The fractions of the filter's bias step from the earlier estimate that are put to the
#: taxels: the filter's own, two shorter ones, and none (the object did not move).
LOCATING_STEPS = (1.0, 0.5, 0.25, 0.0)


def locating_problem(fusion: FusionProblem, earlier: StageEstimate) -> FusionProblem:
    """The last grasp of ``fusion`` alone, fused from ``earlier`` (the estimate of the
    grasps before it): its points, its state as the prior mean and the filter's own
    covariance plus ``Q`` as the prior (the filter steps with its own model), with the
    plane held (:func:`.hypotheses.held_problem`)."""
    problem = replace(
        fusion,
        points_m=earlier.points,
        g_init=np.array(earlier.grasp_g[-1], dtype=float),
        covariance_init=_own_covariance(earlier) + fusion.regrasp_noise,
        grasps=fusion.grasps[-1:],
    )
    return held_problem(problem, _PLANE)


def _own_covariance(estimate: StageEstimate) -> np.ndarray:
    """The filter's own covariance of ``estimate`` (its reported one when it has none)."""
    own = estimate.covariance if estimate.filter_covariance is None else estimate.filter_covariance
    return np.asarray(own, dtype=float)


def earlier_shape_stages(
    fusion: FusionProblem,
    stages: Sequence[StageEstimate],
    refuse: Refuse,
    view: DepthObservation | None,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> list[StageEstimate]:
    """``stages`` (diagnosed, Stage 0 first) with the last stage replaced by the earlier
    shape located by the last grasp (the best-fitting of :data:`LOCATING_STEPS`), when the
    last stage is inconsistent and the earlier shape passes every test, or is the best
    supported model though inconsistent (:func:`_best_supported`). Runs only with two or
    more grasps; the earlier estimate is :func:`.problem.estimate_result` of ``refuse`` on
    the grasps before the last."""
    from pipeline.estimation.problem import estimate_result

    last = stages[-1]
    if len(fusion.grasps) < 2 or last.status != "inconsistent":
        return list(stages)
    started = time.perf_counter()
    before = replace(fusion, grasps=fusion.grasps[:-1])
    earlier = estimate_result(before, refuse(before), started, view, settings, refuse).selected
    if estimate_failed(earlier.status) or len(earlier.grasp_g) != len(before.grasps):
        return list(stages)
    name, verdict = EARLIER_SHAPE, None
    if found := _locate(fusion, earlier, refuse, settings, tree):
        located, step, g = found
        verdict = _judge(fusion, earlier, g, view, settings, tree)
    if verdict is None or not verdict.consistent:
        # A pad the earlier shape cannot explain (a handle) drags the location, or leads
        # the filter astray: the other pads locate it, and all are judged.
        pad = _unexplained_pad(fusion, earlier, settings, tree)
        if pad is not None and (
            found := _locate(without_pad(fusion, pad), earlier, refuse, settings, tree)
        ):
            located, step, g = found
            name = f"{EARLIER_SHAPE} without {pad}"
            verdict = _judge(fusion, earlier, g, view, settings, tree)
    kept = verdict is not None and (verdict.consistent or _best_supported(verdict, earlier, stages))
    if not kept:
        return list(stages)
    grasp_g = (*earlier.grasp_g, g)
    prior = np.asarray(earlier.covariance, dtype=float) + fusion.regrasp_noise
    covariance = shortened_covariance(
        prior,
        unheld_covariance(np.asarray(located.covariance, dtype=float), prior, _PLANE),
        step,
    )
    own = unheld_covariance(
        np.asarray(located.filter_covariance, dtype=float),
        _own_covariance(earlier) + fusion.regrasp_noise,
        _PLANE,
    )
    estimate = stage_estimate(
        last.stage,
        g,
        covariance,
        earlier.points,
        fusion.pivot_m,
        last.iterations + located.iterations,
        located.status,
        last.seconds + time.perf_counter() - started,
        located.active_points,
        located.trace,
        grasp_g,
        own,
    )
    reason = last.consistency.reason if last.consistency is not None else ""
    status = estimate.status if verdict.consistent else "inconsistent"
    replaced = replace(
        estimate,
        status=status,
        consistency=verdict,
        hypothesis=Hypothesis(name, step, reason),
    )
    return [*stages[:-1], replaced]


def _best_supported(
    verdict: Consistency, earlier: StageEstimate, stages: Sequence[StageEstimate]
) -> bool:
    """Whether an earlier shape with ``verdict`` (inconsistent) is kept as the stage the
    evidence supports best: the earlier estimate was consistent with the grasps before, the
    camera accepts it, and it contradicts the taxels no more than every diagnosed stage the
    camera accepts (the stage :func:`.consistency.select_stage` would select in place of any
    of them). An earlier estimate already at odds with its own grasps is not relocated on
    the strength of fitting better than Stage 0: its location can then fit the last grasp
    only by moving far from the object."""
    if earlier.consistency is None or not earlier.consistency.consistent:
        return False
    if not verdict.passes_free_space:
        return False
    accepted = [
        s.consistency.excess
        for s in stages
        if s.consistency is not None and s.consistency.passes_free_space
    ]
    return verdict.excess <= min(accepted, default=np.inf)


def _locate(
    fusion: FusionProblem,
    earlier: StageEstimate,
    refuse: Refuse,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> tuple[StageOutcome, float, np.ndarray] | None:
    """The earlier shape located by ``fusion``'s last grasp: the filter's outcome, and the
    step of :data:`LOCATING_STEPS` whose state fits ``fusion``'s taxels best with that
    state; None when the filter failed. The steps differ only in the bias, which the
    free-space test (made before the bias) does not see: the taxels rank them, and the
    camera judges the chosen one."""
    located = refuse(locating_problem(fusion, earlier))[0]
    if estimate_failed(located.status):
        return None
    start = np.asarray(earlier.grasp_g[-1], dtype=float)
    steps = []
    for step in LOCATING_STEPS:
        g = start + step * (located.g - start)
        steps.append((_judge(fusion, earlier, g, None, settings, tree).nis, step, g))
    _, step, g = min(steps, key=lambda entry: entry[0])
    return located, step, g


def _judge(
    fusion: FusionProblem,
    earlier: StageEstimate,
    g: np.ndarray,
    view: DepthObservation | None,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> Consistency:
    """Every test of the earlier shape with the last grasp's state ``g``: on ``fusion``'s
    taxels, and on the camera's image ``view`` when given."""
    grasp_g = (*earlier.grasp_g, g)
    return assess(earlier.points, g, grasp_g, fusion.pivot_m, fusion.grasps, view, settings, tree)


def _unexplained_pad(
    fusion: FusionProblem,
    earlier: StageEstimate,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> str | None:
    """The one pad of the last grasp (of three or more) without which the earlier shape,
    standing where the earlier grasps left it, fits the taxels, as
    :func:`.outlier_pads.outlier_pad` finds it for Stage 0; otherwise None."""
    start = np.asarray(earlier.grasp_g[-1], dtype=float)

    def explained_without(pad: str) -> bool:
        return _judge(without_pad(fusion, pad), earlier, start, None, settings, tree).consistent

    return sole_explaining_pad(fusion.grasps[-1].pads, explained_without)
