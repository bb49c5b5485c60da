"""A trial's ``result.json``, entry by entry, as the trial (:mod:`pipeline.run.trial`) learns
them.

:class:`TrialDocument` is the one place that knows the layout of a trial's document: the
trial tells it what happened (a view, the hand chosen, a grasp executed, fused or not, the
initial state, why it stopped, the estimate) and it writes the entries, in the order the
format keeps (docs/formats.md); the parts every estimating command shares come from
:mod:`pipeline.run.result_document`. A trial that fails after writing data records how far it
got (:meth:`TrialDocument.fail`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pipeline.catalogue.rest import RestPose
from pipeline.config import Config
from pipeline.io.formats import plan_to_json
from pipeline.planning.hand_choice import HandChoice, choice_to_json
from pipeline.run.result_document import (
    estimate_entries,
    init_to_json,
    record_failure,
    start_document,
    write_document,
)
from pipeline.types import EstimateResult, ObjectPose, SymmetryInit


def pose_to_json(pose: ObjectPose) -> dict[str, Any]:
    return {
        "position": [float(v) for v in pose.position_m],
        "quaternion_xyzw": [float(v) for v in pose.quaternion_xyzw],
    }


class TrialDocument:
    """The ``result.json`` of one trial as it grows; :attr:`data` is the document."""

    def __init__(self, config: Config) -> None:
        settings = config.trial
        self.data = start_document(
            "trial",
            object=settings.object,
            gripper=settings.gripper,
            seed=settings.seed,
            stages_used=dict(config.choices),
            status="running",
            config=config.to_dict(),
        )

    def placed(self, pose: RestPose | None, true_kind: str) -> None:
        """The stable pose the object was placed in (None: upright, as loaded), and the
        kind of symmetry that describes it as it lies
        (:func:`pipeline.symmetry.scoring.true_kind`)."""
        self.data["rest"] = None if pose is None else pose.to_json()
        self.data["true_kind"] = true_kind

    def start_looking(self) -> None:
        """No first grasp has missed yet."""
        self.data["missed_grasps"] = []

    def view(self, pose_seen: ObjectPose, points: int) -> None:
        """The object's pose when the camera saw it and the points of its cloud (a later
        look replaces an earlier one's)."""
        self.data["object_pose_before"] = pose_to_json(pose_seen)
        self.data["points"] = points

    def choice(self, choice: HandChoice) -> None:
        """The hand and grasp chosen, how, and the planner that planned it."""
        self.data["gripper"] = choice.answer.gripper
        self.data["hand"] = choice_to_json(choice)
        if choice.answer.planner:
            self.data["stages_used"]["planner"] = choice.answer.planner
        self.data["plan"] = plan_to_json(choice.plan)

    def start_grasping(self, next_grasp: str | None) -> None:
        """No grasp fused yet; later grasps chosen by ``next_grasp`` (None: one grasp)."""
        self.data["grasps"] = []
        self.data["next_grasp"] = next_grasp

    def first_grasp(self, executed: Mapping[str, Any], pose_after: ObjectPose) -> None:
        """How the first grasp was executed and where it left the object."""
        self.data["grasp"] = executed
        self.data["object_pose_after"] = pose_to_json(pose_after)

    def unfused(self, attempt: Mapping[str, Any], reason: str) -> None:
        """A grasp not fused (:func:`~pipeline.run.trial.attempt_to_json`) and why: the
        first is ``unfused_grasp`` (the trial stops on it or grasps again, :meth:`missed`),
        a later one joins ``unfused_grasps`` (released, and another grasp planned)."""
        if attempt["grasp"] == 1:
            self.data["unfused_grasp"] = attempt
        else:
            self.data.setdefault("unfused_grasps", []).append({**attempt, "reason": reason})

    def missed(self) -> None:
        """The first grasp missed and will be made again: it moves to ``missed_grasps``."""
        self.data["missed_grasps"].append(self.data.pop("unfused_grasp"))

    def initial_state(self, init: SymmetryInit) -> None:
        """Stage 0 as the initialiser refined it, with its best 20 hypotheses."""
        self.data["init"] = init_to_json(init, status=True, hypotheses=20)

    def fused(self, grasp: Mapping[str, Any], pose_after: ObjectPose) -> None:
        """A grasp fused (:func:`~pipeline.run.trial.grasp_to_json`) and where it left the
        object."""
        self.data["grasps"].append(grasp)
        self.data["object_pose_after"] = pose_to_json(pose_after)

    def stopped(self, taxels_in_contact: int, reason: str) -> None:
        """Every fused grasp's taxels in contact, and why grasping stopped."""
        self.data["taxels_in_contact"] = taxels_in_contact
        self.data["stop_reason"] = reason

    def model(self, entry: Mapping[str, Any]) -> None:
        """The model's files and solid (:func:`pipeline.asset.files.write_model`)."""
        self.data["model"] = entry

    def finish(
        self,
        out_dir: Path,
        result: EstimateResult,
        metrics: Sequence[dict[str, Any]],
        timings: Mapping[str, float],
    ) -> None:
        """The final estimate with each stage's metrics, the phases' times; written."""
        self.data.update(
            status=result.final.status, **estimate_entries(result, metrics), timings=timings
        )
        write_document(out_dir, self.data)

    def fail(self, out_dir: Path, reason: str, timings: Mapping[str, float]) -> None:
        """The trial failed with ``reason`` after writing data: written as far as it got."""
        record_failure(out_dir, self.data, reason, timings=timings)
