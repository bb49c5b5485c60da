"""Which hand grasps the object, and with which plan (``trial.gripper``).

Each planner declares the hands it plans for (:attr:`pipeline.stages.GraspPlanner.grippers`).
With a named gripper the configured planner (``planner.use``) plans for it when it names
that hand; otherwise every installed planner that does competes, as below, for that hand
alone (:func:`named_hand_planners`). With ``"auto"`` every installed planner that names an
available hand plans on the cloud (before any hand is in the scene), and the feasible plan
with the highest score wins; planners score on one scale
(:attr:`pipeline.types.GraspPlan.score`), so a hand wins by the quality of the grasp it can
make on this object, not by its name (nor a planner by its name, or by when it was
installed). When no planner finds a feasible grasp, every one plans again on the cloud with
the volume the view leaves hidden under it (:func:`_with_hidden_volume`); when none finds
one then either, the refusal names the object's measured size and every hand's aperture.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from pipeline.config import Config
from pipeline.errors import ConfigError
from pipeline.params import to_toml
from pipeline.planning.grasp_geometry import narrowest_width
from pipeline.planning.hidden_volume import hidden_below
from pipeline.registry import StageRegistry
from pipeline.stages import GraspPlanner
from pipeline.types import GraspCandidate, GraspPlan, GripperSpec, PointCloud, SymmetryInit

#: ``trial.gripper`` value that lets the planners choose the hand.
AUTO = "auto"


def planners_for(registry: StageRegistry, gripper: str) -> list[str]:
    """The installed planners that name the hand ``gripper``, by name."""
    return [
        name
        for name in registry.names("planner")
        if gripper in registry.get("planner", name).cls.grippers
    ]


def named_hand_planners(config: Config, registry: StageRegistry) -> list[str]:
    """The planners that plan for the named hand ``config.trial.gripper``: ``planner.use``
    when it names the hand; else every installed planner that does, to compete; else (no
    planner names it: a world's own hand) ``planner.use``, which may plan for any hand of
    its kind."""
    configured = config.choices["planner"]
    naming = planners_for(registry, config.trial.gripper)
    return [configured] if configured in naming or not naming else naming


def check_planner_is_read(
    config: Config, registry: StageRegistry, changed: Collection[str]
) -> None:
    """Refuse a ``planner.use`` the user chose (in ``changed``, the dotted keys the user
    set, :attr:`Config.changed`) that would not plan: with ``trial.gripper = "auto"``
    every installed planner competes, and a named hand is planned by ``planner.use`` only
    when it names that hand or no planner does (:func:`named_hand_planners`).

    Raises:
        ConfigError: naming ``planner.use``, the hands it plans for and what to do.
    """
    if "planner.use" not in changed:
        return
    chosen = config.choices["planner"]
    gripper = config.trial.gripper
    hands = ", ".join(registry.get("planner", chosen).cls.grippers) or "none"
    if gripper == AUTO:
        raise ConfigError(
            f"config key 'planner.use' ({chosen}) is not read with trial.gripper = 'auto', "
            f"where every installed planner competes for the grasp; name the hand with "
            f"--gripper (planner '{chosen}' plans for: {hands})"
        )
    if chosen not in named_hand_planners(config, registry):
        raise ConfigError(
            f"config key 'planner.use': planner '{chosen}' does not plan for the hand "
            f"'{gripper}' (it plans for: {hands})"
        )


def next_try(hands: tuple[str, ...], used: str) -> str:
    """What to try after a grasp by the hand ``used`` failed (touched too little, was not
    executed, or left an estimate that failed), as a clause to end the message with: the
    world's other hands (``hands``) by name, else another pose of the object."""
    others = [hand for hand in hands if hand != used]
    if others:
        return f"; try --gripper {' or --gripper '.join(others)}"
    return "; try another --yaw"


@dataclass(frozen=True)
class PlannerAnswer:
    """One planner's plan for one hand."""

    gripper: str
    planner: str
    plan: GraspPlan


@dataclass(frozen=True)
class HandChoice:
    """The plan a trial executes and how it was chosen.

    Attributes:
        answer: the chosen hand, its planner and plan (refused when no hand can grasp).
        reason: one line saying why this hand.
        answers: every planner's answer, in the order they were asked.
    """

    answer: PlannerAnswer
    reason: str
    answers: tuple[PlannerAnswer, ...]

    @property
    def plan(self) -> GraspPlan:
        return self.answer.plan


#: Grasps of one hand whose closing lines lie within this angle of each other (deg) close
#: alike: after one missed, a re-plan looks for a grasp unlike it (:func:`like_missed`).
MISSED_LINE_DEG = 20.0


def like_missed(plan: GraspPlan, missed: Sequence[GraspPlan]) -> bool:
    """Whether ``plan`` closes like one of the ``missed`` grasps: the same hand, its closing
    line within :data:`MISSED_LINE_DEG` of that grasp's (a line and its reverse are one)."""
    bound = math.cos(math.radians(MISSED_LINE_DEG))
    return any(
        plan.gripper == other.gripper
        and abs(float(plan.closing_direction[:2] @ other.closing_direction[:2]))
        >= bound
        * float(np.linalg.norm(plan.closing_direction[:2]))
        * float(np.linalg.norm(other.closing_direction[:2]))
        for other in missed
    )


def _plan(
    planner: GraspPlanner,
    cloud: PointCloud,
    proposal: SymmetryInit,
    gripper: GripperSpec,
    missed: Sequence[GraspPlan],
) -> GraspPlan:
    """``planner``'s plan for ``gripper``; after grasps that ``missed``, its best feasible
    grasp unlike them (:func:`like_missed`), refused when every one is like them."""
    plan = planner.plan(cloud, proposal, gripper)
    if not missed or (plan.status == "ok" and not like_missed(plan, missed)):
        return plan
    unlike = [
        p for p in planner.alternatives(cloud, proposal, gripper) if not like_missed(p, missed)
    ]
    if unlike:
        return unlike[0]
    return replace(
        plan,
        status="refused",
        reason=plan.reason
        or f"every feasible grasp closes within {MISSED_LINE_DEG:g} deg of one that missed",
    )


def choose_grasp(
    config: Config,
    registry: StageRegistry,
    cloud: PointCloud,
    proposal: SymmetryInit,
    grippers: Mapping[str, GripperSpec],
    table_height_m: float,
    missed: Sequence[GraspPlan] = (),
    planners: Planners | None = None,
) -> HandChoice:
    """Plan the grasp for ``config.trial.gripper`` (a name in ``grippers``, or ``"auto"``).

    Args:
        grippers: the hands available, by name.
        table_height_m: z of the table top (for the size quoted in a refusal), m.
        missed: earlier grasps of this object whose pads did not touch opposing sides: each
            planner plans its best grasp unlike them (:func:`like_missed`).
        planners: the planners built so far (None: build those asked for).
    """
    planners = planners or Planners(config, registry)
    wanted = config.trial.gripper
    if wanted != AUTO and named_hand_planners(config, registry) == [config.choices["planner"]]:
        planner = planners(config.choices["planner"])
        plan = _plan(planner, cloud, proposal, grippers[wanted], missed)
        answer = PlannerAnswer(wanted, config.choices["planner"], plan)
        return HandChoice(answer, f"trial.gripper = '{wanted}'", (answer,))

    def ask(planned: PointCloud) -> list[PlannerAnswer]:
        answers = []
        for name in registry.names("planner"):
            for gripper in registry.get("planner", name).cls.grippers:
                if gripper in grippers and wanted in (AUTO, gripper):
                    plan = _plan(planners(name), planned, proposal, grippers[gripper], missed)
                    answers.append(PlannerAnswer(gripper, name, plan))
        return answers

    answers = ask(cloud)
    feasible = [a for a in answers if a.plan.status == "ok"]
    hidden = ""
    filled = None if feasible else _with_hidden_volume(cloud)
    if filled is not None:
        again = ask(filled)
        if any(a.plan.status == "ok" for a in again):
            answers, feasible = again, [a for a in again if a.plan.status == "ok"]
            hidden = "; planned with the volume the view leaves hidden under the cloud"
    if not feasible:
        return HandChoice(
            _refusal(answers, cloud, proposal, grippers, table_height_m), "", tuple(answers)
        )
    best = max(feasible, key=lambda a: _score(a.plan))
    others = "; ".join(
        f"{a.gripper} ({a.planner}) "
        + (f"scored {_score(a.plan):.2f}" if a.plan.status == "ok" else f"refused: {a.plan.reason}")
        for a in answers
        if a is not best
    )
    reason = (
        f"{best.gripper} ({best.planner}) has the best feasible grasp, "
        f"score {_score(best.plan):.2f}"
    )
    return HandChoice(best, reason + (f"; {others}" if others else "") + hidden, tuple(answers))


#: Grid step of the volume :func:`_with_hidden_volume` adds (m): a few taxel pitches.
HIDDEN_STEP_M = 0.004


def _with_hidden_volume(cloud: PointCloud) -> PointCloud | None:
    """``cloud`` with the volume the view leaves hidden under it
    (:func:`~pipeline.planning.hidden_volume.hidden_below`, every :data:`HIDDEN_STEP_M`),
    for planning where no hand has a feasible grasp on the cloud alone; None when the
    camera's position is unknown or nothing is hidden.

    Where the camera looks at the object along its mirror plane (a box seen end-on), the
    plane's mirror image is the seen face again, and no hand finds the sides to close on;
    the seen top says how far the object reaches there. Only the planners see the added
    points: the estimator fuses the cloud as seen."""
    if cloud.viewpoint_m is None:
        return None
    hidden = hidden_below(cloud.points, cloud.viewpoint_m, HIDDEN_STEP_M)
    if not len(hidden):
        return None
    points = np.concatenate([cloud.points, hidden])
    return PointCloud(
        points, cloud.frame, viewpoint_m=cloud.viewpoint_m, table_height_m=cloud.table_height_m
    )


def create_planner(config: Config, registry: StageRegistry, name: str) -> GraspPlanner:
    """The planner ``name`` with its configured parameters (its defaults when the config
    has none: with ``trial.gripper = "auto"`` a planner other than ``planner.use`` plans)."""
    params = config.params["planner"].get(name, registry.get("planner", name).cls.Params())
    return registry.create("planner", name, to_toml(params))


class Planners:
    """The planners of one run by name, each built once (:func:`create_planner`) when
    first asked for: a trial plans its first grasp and every later one with them."""

    def __init__(self, config: Config, registry: StageRegistry) -> None:
        self._config = config
        self._registry = registry
        self._built: dict[str, GraspPlanner] = {}

    def __call__(self, name: str) -> GraspPlanner:
        if name not in self._built:
            self._built[name] = create_planner(self._config, self._registry, name)
        return self._built[name]


def _score(plan: GraspPlan) -> float:
    return 0.0 if math.isnan(plan.score) else plan.score


def _refusal(
    answers: list[PlannerAnswer],
    cloud: PointCloud,
    proposal: SymmetryInit,
    grippers: Mapping[str, GripperSpec],
    table_height_m: float,
) -> PlannerAnswer:
    """A refused plan whose reason names the object's size, then each hand's own reason
    for refusing with its opening after it (its planner's reason is what to act on; the
    object's narrowest width is only a summary and may fit a hand that refused for another
    reason)."""
    points = cloud.points
    completed = np.concatenate([points, proposal.plane.mirror(points)])
    width_m, _ = narrowest_width(completed[:, :2])
    height_m = float(np.percentile(points[:, 2], 98.0)) - table_height_m
    hands = "; ".join(
        f"{a.gripper}: {a.plan.reason} ({a.gripper} opens "
        f"{grippers[a.gripper].max_aperture_m * 1e3:.0f} mm)"
        for a in answers
    )
    reason = (
        f"no hand can grasp the object, {width_m * 1e3:.0f} mm wide at its narrowest and "
        f"{height_m * 1e3:.0f} mm tall: {hands or 'no planner plans for an available hand'}"
    )
    template = answers[0].plan if answers else None
    plan = GraspPlan(
        gripper=AUTO,
        status="refused",
        T_robot_hand=np.eye(4) if template is None else template.T_robot_hand,
        pregrasp_height_m=0.0 if template is None else template.pregrasp_height_m,
        opening_m=0.0,
        closing_direction=np.array([1.0, 0.0, 0.0]),
        reason=reason,
        score=0.0,
    )
    return PlannerAnswer(AUTO, "", plan)


def choice_to_json(choice: HandChoice) -> dict[str, Any]:
    """The ``hand`` entry of ``result.json``: the chosen hand and planner, why, and every
    planner's answer with its ranked candidates."""
    return {
        "gripper": choice.answer.gripper,
        "planner": choice.answer.planner,
        "reason": choice.reason or choice.plan.reason,
        "answers": [
            {
                "gripper": a.gripper,
                "planner": a.planner,
                "status": a.plan.status,
                "score": None if math.isnan(a.plan.score) else a.plan.score,
                "reason": a.plan.reason,
                "candidates": [candidate_to_json(c) for c in a.plan.candidates],
            }
            for a in choice.answers
        ],
    }


def candidate_to_json(candidate: GraspCandidate) -> dict[str, Any]:
    """One ranked candidate as JSON (NaN as null)."""

    def number(value: float) -> float | None:
        return None if math.isnan(value) else round(float(value), 6)

    return {
        "closing_angle_deg": number(candidate.closing_angle_deg),
        "height_m": number(candidate.height_m),
        "spread_deg": number(candidate.spread_deg),
        "width_m": number(candidate.width_m),
        "contact_coverage": [number(c) for c in candidate.contact_coverage],
        "tipping_ratio": number(candidate.tipping_ratio),
        "score": number(candidate.score),
        "feasible": candidate.feasible,
        "reason": candidate.reason,
    }
