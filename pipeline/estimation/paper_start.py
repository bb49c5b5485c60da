"""The paper's start as a second hypothesis when the searched start fails (docs/method.md §9).

Stage 1 starts at the best state of a coarse search (:mod:`.bias_search`). The search scores
a few taxels per pad against the model and the prior; where the pads' contacts fit a wider
or narrower completed model about as well as the right one (three pads fix three distances,
the bias and the plane have five components), a state on the wrong side of the object can
score best, and the filter started there diverges or settles on a model the evidence
contradicts. A Stage 2 run after a Stage 1 that fell back starts from Stage 0 with the
prior's gates, and the points it moves can make a wrong model fit: its claim rests on a
chain whose first link failed.

So when a fused stage fails (``diverged``, ``no_correspondence``) or is ``inconsistent``,
and the search moved the start, the estimator fuses again from Stage 0, as the paper does.
The re-fusion's stages replace the fused ones when every one of them passes the
self-diagnosis and none failed: a chain whose every claim holds is preferred to one with a
claim that does not. Otherwise the fused stages stand (and the later hypotheses of §9 may
still revise them). Every test is on the evidence, never on ground truth.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from pipeline.errors import estimate_failed
from pipeline.estimation.consistency import ConsistencySettings, assess
from pipeline.estimation.hypotheses import Refuse
from pipeline.estimation.iekf import FusionProblem, StageOutcome, after_first_view
from pipeline.estimation.problem import outcome_estimate
from pipeline.types import DepthObservation, Hypothesis, StageEstimate

#: ``Hypothesis.name`` of a stage fused again from Stage 0.
NAME = "from Stage 0"


def paper_start_stages(
    fusion: FusionProblem,
    stages: Sequence[StageEstimate],
    outcomes: Sequence[StageOutcome],
    refuse: Refuse,
    view: DepthObservation | None,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> list[StageEstimate]:
    """``stages`` (diagnosed, Stage 0 first; ``outcomes`` the fused stages they came from)
    with the fused stages replaced by a re-fusion from Stage 0 when some fused stage's
    claim fails, Stage 1 started elsewhere, and every stage of the re-fusion passes
    (module docstring)."""
    start = outcomes[0].g_start if outcomes else None
    if start is None or not any(estimate_failed(stage.status) for stage in stages[1:]):
        return list(stages)
    started = time.perf_counter()
    # Stage 0 as the filter starts from it: conditioned on the first grasp's after-view.
    paper = after_first_view(fusion).g_init
    if np.allclose(start, paper):
        return list(stages)
    again = refuse(replace(fusion, g_start=paper))
    verdicts = [
        assess(o.points, o.g, o.grasp_g, fusion.pivot_m, fusion.grasps, view, settings, tree)
        for o in again
    ]
    spent = (time.perf_counter() - started) / len(again)
    holds = all(
        verdict.consistent and not estimate_failed(o.status)
        for o, verdict in zip(again, verdicts, strict=True)
    )
    if not holds:
        return [stages[0], *(replace(s, seconds=s.seconds + spent) for s in stages[1:])]
    revised = [stages[0]]
    for stage, outcome, verdict in zip(stages[1:], again, verdicts, strict=True):
        estimate = outcome_estimate(
            stage.stage,
            outcome,
            fusion.pivot_m,
            stage.iterations + outcome.iterations,
            outcome.status,
            stage.seconds + spent,
        )
        reason = stage.consistency.reason if stage.consistency is not None else ""
        hypothesis = Hypothesis(NAME, 1.0, reason or f"Stage {stage.stage} {stage.status}")
        revised.append(replace(estimate, consistency=verdict, hypothesis=hypothesis))
    return revised
