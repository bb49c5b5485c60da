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

The alternative replaces an inconsistent last stage only when it passes every test of the
self-diagnosis on all the grasps and the camera; its covariance carries the plane's
uncertainty from the earlier estimate (:func:`.hypotheses.unheld_covariance`). Every test is
on the evidence, never on ground truth.

No motion test (:func:`.hypotheses.moved_free_space`) applies: the object was released and
grasped again since the camera saw it, so its motion since then is real.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from ..errors import estimate_failed
from ..types import DepthObservation, Hypothesis, StageEstimate
from .consistency import ConsistencySettings, assess
from .hypotheses import (
    HYPOTHESES,
    Refuse,
    held_problem,
    shortened_covariance,
    unheld_covariance,
)
from .iekf import FusionProblem
from .problem import stage_estimate

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
    last stage is inconsistent and the earlier shape passes every test. Runs only with two
    or more grasps; the earlier estimate is :func:`.problem.estimate_result` of ``refuse``
    on the grasps before the last."""
    from .problem import estimate_result

    last = stages[-1]
    if len(fusion.grasps) < 2 or last.status != "inconsistent":
        return list(stages)
    started = time.perf_counter()
    before = replace(fusion, grasps=fusion.grasps[:-1])
    earlier = estimate_result(before, refuse(before), started, view, settings, refuse).selected
    if estimate_failed(earlier.status) or len(earlier.grasp_g) != len(before.grasps):
        return list(stages)
    problem = locating_problem(fusion, earlier)
    located = refuse(problem)[0]
    if estimate_failed(located.status):
        return list(stages)
    start = np.asarray(earlier.grasp_g[-1], dtype=float)
    steps = []
    # The steps differ only in the bias, which the free-space test (made before the bias)
    # does not see: the taxels rank them, and the camera judges the chosen one.
    for step in LOCATING_STEPS:
        g = start + step * (located.g - start)
        grasp_g = (*earlier.grasp_g, g)
        taxels = assess(
            earlier.points, g, grasp_g, fusion.pivot_m, fusion.grasps, None, settings, tree
        )
        if taxels.consistent:
            steps.append((taxels.nis, step, g, grasp_g))
    if not steps:
        return list(stages)
    _, step, g, grasp_g = min(steps, key=lambda entry: entry[0])
    verdict = assess(
        earlier.points, g, grasp_g, fusion.pivot_m, fusion.grasps, view, settings, tree
    )
    if not verdict.consistent:
        return list(stages)
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
    replaced = replace(
        estimate, consistency=verdict, hypothesis=Hypothesis(EARLIER_SHAPE, step, reason)
    )
    return [*stages[:-1], replaced]
