"""A pad that touched what the mirror image cannot complete (docs/method.md §9).

A three-finger grasp can put one finger on a part that symmetry cannot predict: the YCB
mug's handle, hidden from the camera, lies where the mirrored model has no surface. That
pad's taxels lie centimetres off every model a mirror plane can make, and the filter, asked
to explain them, turns the plane until the completed back reaches them, sweeping through
space the camera saw empty. Stage 0 is then the only stage the camera accepts, and the
touch of the other two pads is lost with the one that misled.

When exactly one pad explains Stage 0's taxel failure (without it, Stage 0 fits the other
pads' taxels), the estimator fuses again without that pad. A fused stage of that re-fusion
replaces an inconsistent fused stage when, on the taxels left, it passes every test of the
self-diagnosis and fits them better than Stage 0 does. With the plane free, as in any
fusion, the bias is not the re-fusion's only lever, so the motion test of
:mod:`.hypotheses` (made for held planes) does not apply: the fused stages are not put to
it either. The replacement is diagnosed on *all* the taxels (``hypothesis.name``
``"without <pad>"``): it stays ``inconsistent`` while the left-out pad is unexplained, as
on a handle. It is consistent when its model explains that pad too: from a far-off
Stage 0, the one pad Stage 0 contradicts can also be the one that leads the filter into a
wrong model, and the other pads alone lead it to the object. Only a grasp with three or
more pads qualifies: two pads left are the least that press from opposing sides. Every
test is on the evidence, never on ground truth.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from pipeline.errors import estimate_failed
from pipeline.estimation.consistency import ConsistencySettings, assess
from pipeline.estimation.hypotheses import Refuse
from pipeline.estimation.iekf import FusionProblem, GraspContacts
from pipeline.estimation.problem import outcome_estimate
from pipeline.types import Consistency, DepthObservation, Hypothesis, StageEstimate


def without_pad(fusion: FusionProblem, pad: str) -> FusionProblem:
    """``fusion`` with the taxels of ``pad`` left out of its last grasp."""
    *earlier, grasp = fusion.grasps
    keep = np.asarray(grasp.pads, dtype=str) != pad
    reduced = GraspContacts(
        positions_m=grasp.positions_m[keep],
        pads=np.asarray(grasp.pads)[keep],
        window=grasp.window[keep],
        noise=grasp.noise[keep],
        normals=None if grasp.normals is None else grasp.normals[keep],
        reported_noise=None if grasp.reported_noise is None else grasp.reported_noise[keep],
        pad_errors_m=None if grasp.pad_errors_m is None else grasp.pad_errors_m[keep],
    )
    return replace(fusion, grasps=(*earlier, reduced))


def sole_explaining_pad(pads: np.ndarray, explained_without: Callable[[str], bool]) -> str | None:
    """The one pad among ``pads`` (a grasp's taxel labels, three or more pads) without which
    the taxels are explained (``explained_without(pad)``); None with fewer pads, or when no
    pad or several do. Two pads left are the least that press from opposing sides."""
    names = [str(pad) for pad in np.unique(np.asarray(pads, dtype=str))]
    if len(names) < 3:
        return None
    explaining = [pad for pad in names if explained_without(pad)]
    return explaining[0] if len(explaining) == 1 else None


def outlier_pad(
    fusion: FusionProblem,
    initial: StageEstimate,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> str | None:
    """The one pad of ``fusion``'s single grasp without which Stage 0 (``initial``) fits the
    other pads' taxels, when Stage 0 fails the taxel test and exactly one such pad exists
    among three or more; otherwise None."""
    verdict = initial.consistency
    if len(fusion.grasps) != 1 or verdict is None or not verdict.nis > verdict.nis_threshold:
        return None

    def explained_without(pad: str) -> bool:
        left = taxels_on_stage_0(without_pad(fusion, pad), initial, settings, tree)
        return left.nis <= left.nis_threshold

    return sole_explaining_pad(fusion.grasps[0].pads, explained_without)


def taxels_on_stage_0(
    fusion: FusionProblem,
    initial: StageEstimate,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> Consistency:
    """The taxel test of Stage 0 (``initial``) against ``fusion``'s taxels. The free-space
    test does not depend on the taxels, and Stage 0's has run already."""
    return assess(
        initial.points,
        fusion.g_init,
        [fusion.g_init] * len(fusion.grasps),
        fusion.pivot_m,
        fusion.grasps,
        None,
        settings,
        tree,
    )


def outlier_pad_stages(
    fusion: FusionProblem,
    stages: Sequence[StageEstimate],
    refuse: Refuse,
    view: DepthObservation | None,
    settings: ConsistencySettings,
    tree: cKDTree,
) -> list[StageEstimate]:
    """``stages`` (diagnosed, Stage 0 first) with each inconsistent fused stage replaced by
    the same stage fused without the :func:`outlier_pad`, when that passes (module
    docstring). Runs only with the camera's image (without it, a plane the pads left can
    swing freely would go unchecked) and when the last stage is inconsistent."""
    initial, last = stages[0], stages[-1]
    if view is None or last.status != "inconsistent":
        return list(stages)
    started = time.perf_counter()
    pad = outlier_pad(fusion, initial, settings, tree)
    if pad is None:
        return list(stages)
    reduced = without_pad(fusion, pad)
    vision = taxels_on_stage_0(reduced, initial, settings, tree)
    outcomes = refuse(reduced)
    spent = time.perf_counter() - started
    revised = list(stages)
    name = f"without {pad}"
    for index, (stage, outcome) in enumerate(zip(stages[1:], outcomes, strict=True), start=1):
        seconds = stage.seconds + spent / len(outcomes)
        if stage.status != "inconsistent" or estimate_failed(outcome.status):
            revised[index] = replace(stage, seconds=seconds)
            continue
        # Diagnosed on the pads left, then on all the taxels (what the stage reports).
        left, verdict = (
            assess(
                outcome.points,
                outcome.g,
                outcome.grasp_g,
                fusion.pivot_m,
                grasps,
                view,
                settings,
                tree,
            )
            for grasps in (reduced.grasps, fusion.grasps)
        )
        # The pads left must support the re-fusion better than vision alone does.
        if not (left.consistent and left.nis < vision.nis):
            revised[index] = replace(stage, seconds=seconds)
            continue
        estimate = outcome_estimate(
            stage.stage,
            outcome,
            fusion.pivot_m,
            stage.iterations + outcome.iterations,
            outcome.status if verdict.consistent else "inconsistent",
            seconds,
        )
        reason = stage.consistency.reason if stage.consistency is not None else ""
        revised[index] = replace(
            estimate, consistency=verdict, hypothesis=Hypothesis(name, 1.0, reason)
        )
    return revised
