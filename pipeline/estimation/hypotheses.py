"""Alternative hypotheses when fusion contradicts the evidence (docs/method.md §9).

The self-diagnosis (:mod:`.consistency`) can say that a fused stage contradicts the taxels
or the camera; selecting Stage 0 then returns vision alone and throws the touch away. When
the fused model is inconsistent but Stage 0 is consistent, the touch is probably right
about the object's *position* and *width* and wrong about the plane's *angle*: an object
that is only nearly symmetric (a cup's handle) lets the contacts turn the mirror plane
until the completed back sweeps through space the camera saw empty. So the estimator fuses
again under each hypothesis of :data:`HYPOTHESES`, with part of the plane held at the
initialiser's value (:func:`held_problem`):

* ``held-angle``: the plane's angle held; the touch corrects the bias, the plane's
  distance and (Stage 2) the points;
* ``held-plane``: the whole plane held; the touch corrects the bias and the points.

A hypothesis' model that fails a test is shortened: the same step from Stage 0, the
longest fraction of it that passes (``<name>, bounded``, :func:`bounded`).

A hypothesis is accepted only when its model passes the self-diagnosis *and* a motion test
the fused stages are not put to: the bias change it makes relative to Stage 0, applied to
the model as the camera saw it, must not carry more points into seen free space than the
test's own false alarms (:func:`moved_free_space`, :func:`motion_limit`). The ordinary
free-space test compares the model with the image before the bias, so a bias that lifts
an object by millimetres is invisible to it (the sedan, §9); held plane components leave
the bias as the touch's only lever, which makes that test necessary. Among the accepted
models the one whose taxels fit best (lowest pad-averaged NIS) replaces the fused stage,
and only when it fits them better than Stage 0 does. Every test is on the evidence, never
on ground truth. A consistent fused stage is never touched, and the re-fusions run only
when the last stage is inconsistent while Stage 0 is consistent.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import ndtri

from pipeline.errors import estimate_failed
from pipeline.estimation.consistency import ConsistencySettings, assess
from pipeline.estimation.geometry import apply_bias, invert_bias, mirror
from pipeline.estimation.iekf import FusionProblem, StageOutcome
from pipeline.estimation.problem import stage_estimate
from pipeline.perception.visibility import free_space_depths
from pipeline.types import Consistency, DepthObservation, Hypothesis, StageEstimate

#: Bisection steps on the step fraction of a bounded hypothesis (resolution 1/64 of the step).
BISECTION_STEPS = 6
#: The hypotheses: the components of ``g = (b_theta, b_x, b_y, b_z, m_r, m_theta)`` each
#: holds at the initialiser's value. The angle alone first: opposed contacts measure the
#: plane's distance well (an object's width) but a nearly symmetric object lets them turn
#: it; then the whole plane.
HYPOTHESES = {"held-angle": (5,), "held-plane": (4, 5)}

#: Re-fuses a problem (Stage 1, then Stage 2 when the estimator runs it).
Refuse = Callable[[FusionProblem], Sequence[StageOutcome]]


@dataclass(frozen=True)
class Candidate:
    """One hypothesis' model of a stage, with its diagnosis.

    Attributes:
        name: the hypothesis (``"held-plane"``, ``"held-plane, bounded"``).
        step: the fraction of the hypothesis' step from Stage 0 that was kept (1: all).
        g: its final ``(6,)`` bias and plane; grasp_g: per grasp.
        points: ``(N, 3)`` its points ``p_n`` (unbiased, frame R).
        consistency: the self-diagnosis, including the motion test.
        still: the motion test passed (the bias change is one the camera could not see).
    """

    name: str
    step: float
    g: np.ndarray
    grasp_g: tuple[np.ndarray, ...]
    points: np.ndarray
    consistency: Consistency
    still: bool

    def no_worse_than(self, initial: Consistency) -> bool:
        """Passes the motion test and the taxel test, and puts no more points in seen free
        space than the limit or ``initial`` (Stage 0's diagnosis), whichever is larger:
        consistent when Stage 0 is, otherwise no more at odds with the image than it."""
        verdict = self.consistency
        allowed = max(verdict.free_space_limit, initial.free_space_violations)
        return (
            self.still
            and verdict.nis <= verdict.nis_threshold
            and verdict.free_space_violations <= allowed
        )


def held_problem(fusion: FusionProblem, held: tuple[int, ...]) -> FusionProblem:
    """``fusion`` with the components ``held`` of ``g`` held at their Stage-0 values.

    The Gaussian prior of ``g`` is conditioned on the held components:
    ``P' = P - P[:, h] P[h, h]^-1 P[h, :]``, whose held rows and columns are zero (set
    exactly), so the gain's held rows are zero (``K = P H^T S^-1``) and every iterate and
    the posterior keep them; the divergence test's half-width there is zero too, which an
    unchanged component passes. Conditioning, not just zeroing, matters for the angle: the
    prior couples ``m_r`` to ``m_theta`` through the pivot's lever arm (§4), and with the
    angle held only the plane's distance from the pivot stays uncertain. The re-grasp noise
    has no plane entries, so later grasps keep the held plane components as well.
    """
    covariance = np.array(fusion.covariance_init, dtype=float)
    h = list(held)
    covariance -= covariance[:, h] @ np.linalg.solve(covariance[np.ix_(h, h)], covariance[h, :])
    covariance[h, :] = 0.0
    covariance[:, h] = 0.0
    return replace(fusion, covariance_init=covariance)


def unheld_covariance(
    posterior: np.ndarray, prior: np.ndarray, held: tuple[int, ...]
) -> np.ndarray:
    """The covariance of ``g`` under a hypothesis, with the held components' uncertainty
    put back: ``posterior`` (the re-fusion's, zero in ``held``) is the uncertainty *given*
    the held values, which were not measured but taken from Stage 0, so their marginal is
    the ``prior``'s ``P_hh`` and the other components follow them by the prior's regression
    ``A = P_fh P_hh^-1``: ``posterior + [A; I] P_hh [A; I]^T``, positive semi-definite. A
    zero there would claim the plane known exactly (the stop rule would stop on it, and
    every next grasp would look as uninformative as the others)."""
    h = list(held)
    free = [i for i in range(len(prior)) if i not in held]
    lift = np.zeros((len(prior), len(h)))
    lift[free] = prior[np.ix_(free, h)] @ np.linalg.inv(prior[np.ix_(h, h)])
    lift[h] = np.eye(len(h))
    covariance = posterior + lift @ prior[np.ix_(h, h)] @ lift.T
    return (covariance + covariance.T) / 2.0


def shortened_covariance(prior: np.ndarray, posterior: np.ndarray, step: float) -> np.ndarray:
    """The covariance of a state taken only ``step`` of the way from the prior mean to the
    posterior one (a bounded hypothesis, a shortened location).

    Its error is ``(1 - s) e_prior + s e_post``, and after a Kalman update
    ``Cov(e_prior, e_post) = P_post``, so the covariance is
    ``(1 - s)^2 P_prior + (1 - (1 - s)^2) P_post``: the posterior at ``s = 1``, the prior at
    ``s = 0``. Reporting the posterior for a shortened step would claim what the taxels
    would have told had the state gone all the way."""
    kept = (1.0 - step) ** 2
    covariance = kept * prior + (1.0 - kept) * posterior
    return (covariance + covariance.T) / 2.0


def moved_free_space(
    points_m: np.ndarray,
    g: np.ndarray,
    g_reference: np.ndarray,
    pivot_m: np.ndarray,
    view: DepthObservation,
    tolerance_m: float,
) -> int:
    """Model points that the bias change from ``g_reference`` moves into seen free space.

    The model as the camera saw it (``p`` and ``f_m(p)``, frame R before the bias) is moved
    by ``f_b(g_reference)^-1 o f_b(g)``: the rigid motion the hypothesis claims the object
    made beyond the one Stage 0 already assumed. Counted are the points further than
    ``tolerance_m`` in front of the measurement after that move but not before it, so the
    count measures the motion alone (zero for no bias change), not the completion's own
    grazing of the silhouette, which the ordinary test already bounds.

    Args:
        points_m: ``(N, 3)`` the model's points ``p`` (unbiased, frame R).
        g, g_reference: the hypothesis' and Stage 0's ``(6,)`` states.
        pivot_m: the bias pivot.
        view: the camera's depth image.
        tolerance_m: how far in front of the measurement a point may lie (m).
    """
    seen = np.vstack([points_m, mirror(points_m, g)])
    moved = invert_bias(apply_bias(seen, g, pivot_m), g_reference, pivot_m)
    before, after = (
        free_space_depths(model, view.depth_m, view.intrinsics, view.T_robot_camera)
        for model in (seen, moved)
    )
    return int(np.count_nonzero((after > tolerance_m) & ~(before > tolerance_m)))


def motion_limit(model_points: int, alpha: float) -> int:
    """The most points a bias change may move into seen free space: the ``1 - alpha``
    quantile (normal approximation) of the test's own false alarms among ``model_points``
    points, each a violation with probability ``alpha``. A rigid motion the camera could
    have seen (a lift of the whole object, a slide out of its silhouette) exceeds it."""
    expected = model_points * alpha
    return int(np.ceil(expected + ndtri(1.0 - alpha) * np.sqrt(expected * (1.0 - alpha))))


def diagnose(
    fusion: FusionProblem,
    name: str,
    step: float,
    g: np.ndarray,
    grasp_g: Sequence[np.ndarray],
    points_m: np.ndarray,
    view: DepthObservation,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> Candidate:
    # Nine parameters: a numeric kernel given one hypothesis' state and what it is checked on.
    """A hypothesis' model diagnosed by :func:`~.consistency.assess` plus the motion test
    (:func:`moved_free_space` against :func:`motion_limit`); a failed motion test is added
    to the verdict's reason."""
    verdict = assess(points_m, g, grasp_g, fusion.pivot_m, fusion.grasps, view, settings, tree)
    moved = moved_free_space(
        points_m, g, fusion.g_init, fusion.pivot_m, view, settings.free_space_tolerance_m
    )
    limit = motion_limit(2 * len(points_m), settings.alpha)
    if moved > limit:
        reason = (
            f"its bias moves {moved} model points into space the camera saw empty (limit {limit})"
        )
        verdict = replace(
            verdict, consistent=False, reason="; ".join(filter(None, (verdict.reason, reason)))
        )
    return Candidate(name, step, g, tuple(grasp_g), points_m, verdict, moved <= limit)


def interpolated(
    fusion: FusionProblem,
    full: Candidate,
    t: float,
    view: DepthObservation,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> Candidate:
    """``full``'s step from Stage 0 shortened to the fraction ``t``, diagnosed: states and
    points move linearly from Stage 0 (``t = 0``) to ``full`` (``t = 1``)."""
    g0 = fusion.g_init
    return diagnose(
        fusion,
        f"{full.name}{Hypothesis.BOUNDED_SUFFIX}",
        t,
        g0 + t * (full.g - g0),
        [g0 + t * (g_k - g0) for g_k in full.grasp_g],
        fusion.points_m + t * (full.points - fusion.points_m),
        view,
        settings,
        tree,
    )


def bounded(
    fusion: FusionProblem,
    full: Candidate,
    initial: Consistency,
    view: DepthObservation,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> list[Candidate]:
    """Shortened steps of ``full`` that are no worse than Stage 0
    (:meth:`Candidate.no_worse_than` ``initial``).

    Bisection finds the longest such fraction ``t_max`` of the step (Stage 0, ``t = 0``,
    qualifies by the caller's condition; ``full``, ``t = 1``, does not), resolution
    ``1 / 2^BISECTION_STEPS``; also returned are ``t_max / 2`` and ``t_max / 4`` when they
    qualify, since the taxels may fit a shorter step better (the filter's weighted means
    and the diagnosis' surface patches need not agree on a nearly symmetric object).
    """
    low, high, longest = 0.0, 1.0, None
    for _ in range(BISECTION_STEPS):
        middle = 0.5 * (low + high)
        candidate = interpolated(fusion, full, middle, view, settings, tree)
        if candidate.no_worse_than(initial):
            low, longest = middle, candidate
        else:
            high = middle
    if longest is None:
        return []
    shorter = (interpolated(fusion, full, low / d, view, settings, tree) for d in (2, 4))
    return [longest, *(c for c in shorter if c.no_worse_than(initial))]


def stage_candidates(
    fusion: FusionProblem,
    name: str,
    outcome: StageOutcome,
    initial: Consistency,
    view: DepthObservation,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> list[Candidate]:
    """Hypothesis ``name``'s model of one stage (``outcome``) when it is no worse than
    Stage 0 (diagnosis ``initial``), else its shortened steps that are."""
    if estimate_failed(outcome.status):
        return []
    full = diagnose(
        fusion, name, 1.0, outcome.g, outcome.grasp_g, outcome.points, view, settings, tree
    )
    if full.no_worse_than(initial):
        return [full]
    return bounded(fusion, full, initial, view, settings, tree)


def revise(
    fusion: FusionProblem,
    stages: Sequence[StageEstimate],
    refuse: Refuse,
    view: DepthObservation | None,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> list[StageEstimate]:
    """``stages`` (diagnosed, Stage 0 first) with inconsistent fused stages replaced by
    their best hypothesis no worse than Stage 0, when there is one.

    Runs only when the last stage is inconsistent (status ``inconsistent``) while Stage 0
    is worth holding (:func:`holdable`), and only with the camera's image (the motion
    test needs it). A replacement is ``inconsistent`` when Stage 0 was (then it is at
    most as much at odds with the image and fits the taxels better).
    """
    initial, last = stages[0], stages[-1]
    if view is None or last.status != "inconsistent" or not holdable(initial, last):
        return list(stages)
    refused = {name: refuse(held_problem(fusion, held)) for name, held in HYPOTHESES.items()}
    revised = list(stages)
    for index, stage in enumerate(stages[1:], start=1):
        if stage.status != "inconsistent":
            continue
        started = time.perf_counter()
        # Each re-fusion's stage counts in the stage it stands in for.
        spent = sum(outcomes[index - 1].seconds for outcomes in refused.values())
        candidates = [
            (candidate, outcomes[index - 1], HYPOTHESES[name])
            for name, outcomes in refused.items()
            for candidate in stage_candidates(
                fusion, name, outcomes[index - 1], initial.consistency, view, settings, tree
            )
        ]
        seconds = stage.seconds + spent + time.perf_counter() - started
        best = min(candidates, key=lambda entry: entry[0].consistency.nis, default=None)
        # The touch must support the hypothesis better than vision alone does; otherwise
        # the step it takes is not the contacts' evidence but the filter's.
        if best is not None and best[0].consistency.nis < initial.consistency.nis:
            revised[index] = _as_stage(stage, *best, fusion, seconds)
        else:
            revised[index] = replace(stage, seconds=seconds)
    return revised


def holdable(initial: StageEstimate, last: StageEstimate) -> bool:
    """Stage 0 is worth holding on to: the taxels do not contradict it, and the evidence
    contradicts it no more than the last stage (always so when Stage 0 is consistent). When
    only the image contradicts it (an initialiser's plane whose mirror image grazes seen
    free space), a hypothesis must be no more at odds with the image than it."""
    verdict = initial.consistency
    return (
        verdict is not None
        and last.consistency is not None
        and verdict.nis <= verdict.nis_threshold
        and verdict.excess <= last.consistency.excess
    )


def _as_stage(
    fused: StageEstimate,
    chosen: Candidate,
    outcome: StageOutcome,
    held: tuple[int, ...],
    fusion: FusionProblem,
    seconds: float,
) -> StageEstimate:
    """The stage estimate of ``chosen`` (from the re-fusion ``outcome``, components
    ``held`` at Stage 0's values) in place of ``fused``, recording the hypothesis and why
    the fused model was set aside.

    Its covariance is the re-fusion's posterior with the held components' prior
    uncertainty put back (:func:`unheld_covariance`), for a shortened step moved back
    toward the prior's (:func:`shortened_covariance`); the filter's own covariance is the
    re-fusion's, unshortened. ``seconds`` is the fused stage's time plus what the
    hypotheses cost.
    """
    prior = np.asarray(fusion.covariance_init, dtype=float)
    posterior = unheld_covariance(np.asarray(outcome.covariance, dtype=float), prior, held)
    estimate = stage_estimate(
        fused.stage,
        chosen.g,
        shortened_covariance(prior, posterior, chosen.step),
        chosen.points,
        fusion.pivot_m,
        fused.iterations + outcome.iterations,
        outcome.status if chosen.consistency.consistent else "inconsistent",
        seconds,
        outcome.active_points,
        outcome.trace,
        chosen.grasp_g,
        unheld_covariance(np.asarray(outcome.filter_covariance, dtype=float), prior, held),
    )
    hypothesis = Hypothesis(
        name=chosen.name,
        step=chosen.step,
        replaced=fused.consistency.reason if fused.consistency is not None else "",
    )
    return replace(estimate, consistency=chosen.consistency, hypothesis=hypothesis)
