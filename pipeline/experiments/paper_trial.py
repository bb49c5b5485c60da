"""One trial of a paper experiment, from its task params to its flat result row.

Result rows (``k`` = stage 0, 1, 2): ``failed`` (None, or the reason a stage refused:
empty segmentation, refused or unexecuted grasp, rejected initialisation), ``status`` (the
final stage's, or ``"failed"``), ``diverged``, ``points``, ``taxels_in_contact``,
``gripper`` (the hand that grasped), ``selected_stage``, ``rest_pose``,
``rest_probability``, ``rest_keeps_vertical`` and ``true_kind`` (the object's resting pose
and the kind of symmetry that describes it as it lies, also on a failed trial's row),
``seconds``, ``timings``, and per stage ``stage{k}_status``, ``stage{k}_iterations``,
``stage{k}_hypothesis`` (the alternative hypothesis its model comes from, empty for the
fused model; docs/method.md §9), ``stage{k}_deviation_{min,q1,median,q3,max,mean}_mm``
and every scalar metric of :func:`pipeline.metrics.evaluation.evaluate_stage` as
``stage{k}_<metric>`` (thickness, side angle, diameter, plane errors, and the shape scores:
``chamfer_mm``, ``precision_2mm``, ``recall_2mm``, ``fscore_2mm``, the same at 5 mm,
``iou``); ``model_watertight`` (whether every stage's mesh the trial wrote is closed; absent when
it wrote none); ``opposing_contacts`` (whether the first grasp's pads pressed from opposing
sides) and, once a grasp was executed, ``grasp_tilt_deg``, ``grasp_shift_mm`` and
``grasp_reapproaches``. A failed trial's row says where it stopped (``failed_stage``) and
whether the planners refused (``refused``): :func:`failure_fields`.
"""

from __future__ import annotations

import contextlib
import json
import tempfile
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline.errors import StageFailure
from pipeline.experiments.common import plugin_registry
from pipeline.experiments.paper_tasks import trial_config
from pipeline.experiments.rows import STAGES, rest_fields
from pipeline.io.formats import consistency_fields, hypothesis_field

if TYPE_CHECKING:
    from pipeline.run.trial import TrialRecord

#: Where a trial can stop short of an estimate (:func:`failure_fields`), in pipeline order;
#: a finished trial whose estimate is worse than vision's counts as ``estimator``.
FAILURE_STAGES = ("segmentation", "plane", "planner", "contact", "estimator")

#: A trial diverged when the estimator says so, or when its final median deviation from the
#: true surface exceeds Stage 0's by more than this (mm).
DIVERGED_GROWTH_MM = 5.0


def run_paper_trial(params: Mapping[str, Any]) -> dict[str, Any]:
    """Run one trial from its task params and return its result row (see the module doc).

    The trial runs with :func:`trial_config`. Its folder is replaced whole (a re-run never
    mixes files of two runs). A :class:`StageFailure` becomes a row with ``failed`` set; any other
    exception propagates (the sweep engine records it as an error row).
    """
    with paper_trial(params) as (row, _):
        return row


@contextlib.contextmanager
def paper_trial(
    params: Mapping[str, Any],
) -> Iterator[tuple[dict[str, Any], TrialRecord | None]]:
    """:func:`run_paper_trial`'s row and the finished trial's record (None when a stage
    refused), with the trial's folder (``record.out_dir``) kept until the block ends, also
    when ``trial_dir`` is None (a temporary folder)."""
    from pipeline.io.outdir import staged_output
    from pipeline.run.trial import run_trial

    registry = plugin_registry()
    config = trial_config(params)
    started = time.perf_counter()
    with contextlib.ExitStack() as stack:
        trial_dir = params.get("trial_dir")
        if trial_dir is None:
            trial_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="symfuse-"))
        try:
            with staged_output(Path(trial_dir), overwrite=True) as staging:
                record = run_trial(config, registry, staging)
        except StageFailure as exc:
            recorded = Path(trial_dir) / "result.json"
            document = json.loads(recorded.read_text()) if recorded.exists() else {}
            failed = {
                "failed": str(exc),
                "status": "failed",
                "diverged": False,
                **rest_fields(document.get("rest")),
                "true_kind": document.get("true_kind"),
                **failure_fields(document),
                "seconds": time.perf_counter() - started,
            }
            yield failed, None
            return
        row = trial_row(record.document, record.metrics)
        row["seconds"] = time.perf_counter() - started
        yield row, replace(record, out_dir=Path(trial_dir))


def trial_row(document: Mapping[str, Any], metrics: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The flat result row of a finished trial from its ``result.json`` document and the
    per-stage metrics (deviations converted to millimetres)."""
    row: dict[str, Any] = {
        "failed": None,
        "status": document["status"],
        "points": document.get("points"),
        "taxels_in_contact": document.get("taxels_in_contact"),
        "timings": dict(document.get("timings", {})),
        "selected_stage": document.get("selected_stage"),
        "gripper": document.get("gripper"),
        **rest_fields(document.get("rest")),
        "true_kind": document.get("true_kind"),
    }
    for stage_json, stage_metrics in zip(document["stages"], metrics, strict=True):
        prefix = f"stage{stage_json['stage']}"
        row[f"{prefix}_status"] = stage_json.get("status")
        row[f"{prefix}_iterations"] = stage_json.get("iterations")
        row.update(consistency_fields(prefix, stage_json.get("consistency")))
        row.update(hypothesis_field(prefix, stage_json.get("hypothesis")))
        for name, value in stage_metrics.items():
            if name == "deviation_m":
                for field, metres in value.items():
                    if field != "count":
                        row[f"{prefix}_deviation_{field}_mm"] = 1e3 * float(metres)
            elif name == "thickness_error" and isinstance(value, str):
                row[f"{prefix}_thickness_fit_failed"] = value
            elif isinstance(value, int | float):
                row[f"{prefix}_{name}"] = float(value)
    row["diverged"] = is_diverged(row)
    model = document.get("model") or {}
    if model.get("status") == "ok":
        row["model_watertight"] = all(model["watertight"].values())
    row.update(grasp_motion_fields(document))
    row["opposing_contacts"] = True  # the first grasp was fused: its pads opposed
    if document.get("next_grasp"):
        row["stop_reason"] = document.get("stop_reason")
        row["grasps_made"] = len(document["grasps"])
        for entry in document["grasps"]:
            row.update(grasp_fields(entry))
        for unfused in document.get("unfused_grasps", []):
            row.update(attempt_fields(unfused, fused=False))
    return row


def grasp_motion_fields(document: Mapping[str, Any]) -> dict[str, Any]:
    """How the (first) grasp moved the object, from a trial's ``result.json`` document:
    ``grasp_tilt_deg`` (its up axis tilted), ``grasp_shift_mm`` (its centre moved) and
    ``grasp_reapproaches``; empty when no grasp was executed."""
    grasp = document.get("grasp") or {}
    if not grasp.get("executed"):
        return {}
    return {
        "grasp_tilt_deg": grasp.get("object_tilt_deg"),
        "grasp_shift_mm": grasp.get("object_shift_mm"),
        "grasp_reapproaches": grasp.get("reapproaches"),
    }


def failure_fields(document: Mapping[str, Any]) -> dict[str, Any]:
    """Where a trial that raised :class:`StageFailure` stopped, from the ``result.json`` it
    wrote (``{}`` when it wrote none): ``failed_stage``, one of :data:`FAILURE_STAGES`
    (``segmentation``: no object cloud; ``plane``: the initialiser gave no plane;
    ``planner``: no hand's planner found a grasp, or the hand could not execute it;
    ``contact``: the grasp touched one side only or nothing, and so did every grasp after
    it, ``trial.retries``; ``estimator``: a later stage refused), ``refused`` (whether the
    planners refused: the reason then names the measurement that rules each hand out),
    ``opposing_contacts`` and :func:`grasp_motion_fields`."""
    plan = document.get("plan") or {}
    grasp = document.get("grasp") or {}
    missed = bool(document.get("missed_grasps"))  # every later grasp was refused
    if "points" not in document:
        stage = "segmentation"
    elif not plan:
        stage = "plane"
    elif plan.get("status") != "ok" or not grasp.get("executed"):
        stage = "planner"
    elif "unfused_grasp" in document or (missed and "init" not in document):
        stage = "contact"
    elif (document.get("init") or {}).get("status") != "ok":
        stage = "plane"
    else:
        stage = "estimator"
    return {
        "failed_stage": stage,
        "refused": bool(plan) and plan.get("status") != "ok",
        "opposing_contacts": False,
        **grasp_motion_fields(document),
    }


def attempt_fields(entry: Mapping[str, Any], fused: bool) -> dict[str, Any]:
    """The row fields of any grasp a multi-grasp trial made (``grasp{k}_...``), fused or
    not (a later grasp released unfused): its hand, the planner's score of its plan (in
    [0, 1]; None when the planner gives none), and how far it moved the object (mm, deg)."""
    prefix = f"grasp{entry['grasp']}"
    return {
        f"{prefix}_fused": fused,
        f"{prefix}_gripper": entry["gripper"],
        f"{prefix}_planner_score": entry.get("plan", {}).get("score"),
        f"{prefix}_object_shift_mm": entry.get("object_shift_mm"),
        f"{prefix}_object_turn_deg": entry.get("object_turn_deg"),
    }


def grasp_fields(entry: Mapping[str, Any]) -> dict[str, Any]:
    """The row fields of one fused grasp of a multi-grasp trial (``grasp{k}_...``): those of
    :func:`attempt_fields`, how it was chosen, its taxels, and Stage 2's and the selected
    stage's deviation, plane errors, status and consistency after fusing it, with the stop
    rule's two stds and the hidden side's with the object's place (mm), and the alternative
    hypothesis each stage's model comes from."""
    prefix = f"grasp{entry['grasp']}"
    fields: dict[str, Any] = {
        **attempt_fields(entry, fused=True),
        f"{prefix}_strategy": entry["chosen_by"]["strategy"],
        f"{prefix}_taxels": entry["taxels_in_contact"],
        f"{prefix}_selected_stage": entry["selected_stage"],
        f"{prefix}_offset_std_mm": entry["uncertainty"]["plane_offset_std_mm"],
        f"{prefix}_hidden_std_mm": entry["uncertainty"]["hidden_side_std_mm"],
        f"{prefix}_shape_std_mm": entry["uncertainty"]["hidden_shape_std_mm"],
    }
    for label, stage in (
        ("stage2", entry["stages"][-1]),
        ("selected", entry["stages"][entry["selected_stage"]]),
    ):
        metrics = stage["metrics"]
        consistency = stage.get("consistency") or {}
        fields.update(
            {
                f"{prefix}_{label}_status": stage["status"],
                f"{prefix}_{label}_consistent": consistency.get("consistent"),
                f"{prefix}_{label}_deviation_median_mm": 1e3 * metrics["deviation_m"]["median"],
                f"{prefix}_{label}_plane_angle_error_deg": metrics.get("plane_angle_error_deg"),
                f"{prefix}_{label}_plane_offset_error_mm": metrics.get("plane_offset_error_mm"),
                **hypothesis_field(f"{prefix}_{label}", stage.get("hypothesis")),
            }
        )
    return fields


def is_diverged(row: Mapping[str, Any]) -> bool:
    """See :data:`DIVERGED_GROWTH_MM`."""
    last = max((k for k in STAGES if f"stage{k}_status" in row), default=None)
    if last is None:
        return False
    if row[f"stage{last}_status"] == "diverged":
        return True
    first = row.get("stage0_deviation_median_mm")
    final = row.get(f"stage{last}_deviation_median_mm")
    if first is None or final is None:
        return False
    return bool(final - first > DIVERGED_GROWTH_MM)
