"""The headline benchmark: every object grasped and fused as a new user would, trial by trial.

Every catalogue object, and every scanned mesh ``DIR/*/textured.obj`` when the sweep is
given ``--scans DIR`` (the YCB scans, for instance), stands at 10 object yaws uniform over a
full turn (seeded, the same yaws for every object; ``--repeats N`` changes the count,
``--quick`` keeps one yaw of two objects), each with its own seed (so its own calibration
error, depth noise and taxel noise). Each is one full trial as ``symfuse trial`` runs it:
the hand chosen by ``trial.gripper = "auto"``, the planners' own ranked grasp, the default
initialiser, one grasp. The seeds follow from the task keys alone, so ``--estimator icp``
or ``mirror-only`` runs the same scenes, views and grasps and its report compares with the
IEKF's row by row.

Per object the report gives the share of trials grasped with pads on opposing sides, the
trials refused (with the planners' measured reason), those whose grasp tipped the object
(tilted it more than :data:`TIPPED_DEG`), those whose fused result is no worse than vision
(the selected stage at most :data:`NO_WORSE_MM` worse than Stage 0, by the median
deviation) and those the estimator flagged (a failed final status); the median over trials
of the median deviation, the Chamfer distance and the F-score at 5 mm per stage; and where
each trial that did not end fused and no worse failed (:data:`FAILURE_STAGES`). Over the
trials that wrote a model: those whose every stage's mesh is closed, and those whose
selected mesh is as good a model as its points (:func:`model_lines`). Every task
has a row: a trial that stopped early has the reason it stopped, one that raised has its
error (counted ``raised``).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import estimate_failed
from pipeline.experiments import ExperimentOptions, SweepTask, explore
from pipeline.experiments.common import fmt, plugin_registry, task_seed
from pipeline.experiments.definitions import TRIAL_WORKER_IMPORTS
from pipeline.experiments.init import yaws_deg
from pipeline.experiments.paper_tasks import paper_task, sweep_params, user_settings
from pipeline.experiments.paper_trial import FAILURE_STAGES, run_paper_trial
from pipeline.experiments.rows import value
from pipeline.experiments.sweep import write_csv

NAME = "objects"
#: Each task is a full trial: the workers load its modules once.
WORKER_IMPORTS = TRIAL_WORKER_IMPORTS

DESCRIPTION = (
    "every object (catalogue, and --scans DIR) at 10 seeded yaws, one grasp with --gripper "
    "auto: opposing contacts, refusals, tipping, fused no worse than vision, failure stages"
)
#: The experiment reads the sweep's ``--scans`` folder.
READS_SCANS = True
YAWS = 10
QUICK_YAWS = 1
QUICK_OBJECTS = ("cd_drive", "spray_bottle")
#: A fused result is no worse than vision when the selected stage's median deviation is at
#: most this much above Stage 0's (mm): the deviation's own spread between repeated renders
#: of one scene.
NO_WORSE_MM = 0.2
#: A grasp tipped the object when it tilted its up axis by more than this (deg).
TIPPED_DEG = 5.0
#: The targets on every object some hand can hold: shares of its trials (opposing contacts,
#: fused no worse than vision), and the median selected-stage deviation over all trials (mm).
OPPOSING_TARGET = 0.90
NO_WORSE_TARGET = 0.95
DEVIATION_TARGET_MM = 3.0
#: Targets of the model files: every stage's mesh closed in this share of the trials that
#: wrote a model, and the selected stage's mesh a model as good as its points, its Chamfer
#: distance to the truth at most this factor of theirs.
WATERTIGHT_TARGET = 0.98
MESH_CHAMFER_FACTOR = 1.10
#: Where a trial that did not end fused and no worse than vision failed: the stages of
#: :data:`~pipeline.experiments.paper_trial.FAILURE_STAGES`, and ``raised`` (an exception:
#: a bug).
TAXONOMY = (*FAILURE_STAGES, "raised")


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    from pipeline.config import load_config

    count = QUICK_YAWS if options.quick else (options.repeats or YAWS)
    init = load_config(plugin_registry(), settings=user_settings(options)).choices["initialiser"]
    found = explore.objects(options)
    if options.quick:
        found = [(label, name) for label, name in found if label in QUICK_OBJECTS]
    result = []
    # Yaw by yaw over every object: a sweep stopped early has covered every object alike.
    for index, yaw in enumerate(yaws_deg(options.seed, count)):
        for label, name in found:
            key = f"{label}/yaw{index:02d}"
            params = {
                "object": name,
                "label": label,
                "init": init,
                "gripper": "auto",
                "paper_grasp": False,
                "yaw_deg": float(yaw),
                "seed": task_seed(options.seed, key),
                "overrides": ["trial.pictures=false"],
                **sweep_params(options, key),
            }
            result.append(paper_task(key, params))
    return result


def run_one(params: dict) -> dict[str, Any]:
    return run_paper_trial(params)


# ---------------------------------------------------------------- one row


def finished(row: Mapping[str, Any]) -> bool:
    """Whether the trial ran to an estimate (it neither raised nor stopped early)."""
    return "error" not in row and not row.get("failed")


def selected_deviation(row: Mapping[str, Any]) -> float:
    """The median deviation of the stage the estimator selected (mm); NaN if none."""
    stage = row.get("selected_stage")
    return math.nan if stage is None else value(row, f"stage{stage}_deviation_median_mm")


def selected_value(row: Mapping[str, Any], metric: str) -> float:
    """``metric`` of the selected stage (``stage{k}_<metric>``); NaN if none."""
    stage = row.get("selected_stage")
    return math.nan if stage is None else value(row, f"stage{stage}_{metric}")


def no_worse(row: Mapping[str, Any]) -> bool:
    """Whether the trial fused its grasp and the selected stage is at most
    :data:`NO_WORSE_MM` worse than Stage 0 (median deviation)."""
    if not finished(row):
        return False
    stage0, chosen = value(row, "stage0_deviation_median_mm"), selected_deviation(row)
    return bool(np.isfinite(chosen) and chosen <= stage0 + NO_WORSE_MM)


def tipped(row: Mapping[str, Any]) -> bool:
    """Whether the grasp tilted the object by more than :data:`TIPPED_DEG`."""
    return value(row, "grasp_tilt_deg") > TIPPED_DEG


def failure_stage(row: Mapping[str, Any]) -> str | None:
    """Where the trial failed (one of :data:`TAXONOMY`), or None when it ended fused and
    no worse than vision."""
    if "error" in row:
        return "raised"
    if row.get("failed"):
        return row.get("failed_stage") or "estimator"
    return None if no_worse(row) else "estimator"


def refusal(row: Mapping[str, Any]) -> str | None:
    """The planners' reason for refusing the trial's object, or None."""
    return row.get("failed") if row.get("refused") else None


# ---------------------------------------------------------------- the summary


def _share(count: int, total: int) -> str:
    return f"{count}/{total} ({100.0 * count / total:.0f} %)" if total else "-"


def _median(values: Sequence[float]) -> float:
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else math.nan


def held(group: Sequence[Mapping[str, Any]]) -> bool:
    """Whether some hand can hold the object: the planners did not refuse every trial."""
    return not all(refusal(row) for row in group)


def meets_targets(group: Sequence[Mapping[str, Any]]) -> bool:
    """Whether an object's trials meet :data:`OPPOSING_TARGET` and :data:`NO_WORSE_TARGET`
    (every trial counts, refused ones as misses)."""
    n = len(group)
    opposing = sum(bool(row.get("opposing_contacts")) for row in group)
    return opposing >= OPPOSING_TARGET * n and sum(map(no_worse, group)) >= NO_WORSE_TARGET * n


def summary_lines(rows: Sequence[Mapping[str, Any]], by_object: Mapping[str, list]) -> list[str]:
    """The headline: over every trial, and the objects some hand can hold that meet the
    targets."""
    n = len(rows)
    opposing = sum(bool(row.get("opposing_contacts")) for row in rows)
    better = sum(map(no_worse, rows))
    held_objects = [label for label, group in by_object.items() if held(group)]
    met = [label for label in held_objects if meets_targets(by_object[label])]
    stage2 = _median([value(row, "stage2_deviation_median_mm") for row in rows if finished(row)])
    chosen = _median([selected_deviation(row) for row in rows if finished(row)])
    return [
        "| trials | objects | some hand holds | meet the targets | opposing contacts "
        "| fused no worse than vision | median deviation: Stage 2 / selected (mm) |",
        "|---|---|---|---|---|---|---|",
        f"| {n} | {len(by_object)} | {len(held_objects)} | {len(met)} | {_share(opposing, n)} "
        f"| {_share(better, n)} | {fmt(stage2, 2)} / {fmt(chosen, 2)} |",
    ]


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv``, ``objects.png`` and ``report.md`` (see the module doc)."""
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    by_object: dict[str, list[Mapping[str, Any]]] = {}
    for row in rows:
        by_object.setdefault(row["params"]["label"], []).append(row)
    estimator = rows[0]["params"]["estimator"] if rows else "-"
    lines = [
        f"# Every object, one grasp each, estimator `{estimator}`",
        "",
        "Each object at seeded yaws, one full trial each (`--gripper auto`, the planners' own "
        f"grasp). Targets on every object some hand can hold: opposing contacts in at least "
        f"{100 * OPPOSING_TARGET:.0f} % of its trials, the fused result no worse than vision "
        f"(the selected stage at most {NO_WORSE_MM:g} mm worse than Stage 0, median "
        f"deviation) in at least {100 * NO_WORSE_TARGET:.0f} %; the median selected deviation "
        f"over all trials at most {DEVIATION_TARGET_MM:g} mm.",
        "",
        *summary_lines(rows, by_object),
        "",
        "## Per object",
        "",
        f"Shares of the object's trials. Tipped: tilted more than {TIPPED_DEG:g} deg by the "
        "grasp. Inconsistent: the estimate's final status failed (inconsistent, diverged, no "
        "correspondence). A target missed is marked `*`.",
        "",
        "| object | trials | hands | opposing contacts | refused | tipped "
        "| no worse than vision | inconsistent | taxels (median) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, group in by_object.items():
        n = len(group)
        hands = Counter(row.get("gripper") for row in group if finished(row))
        opposing = sum(bool(row.get("opposing_contacts")) for row in group)
        better = sum(map(no_worse, group))
        flagged = sum(finished(row) and estimate_failed(str(row.get("status"))) for row in group)
        miss = held(group)
        lines.append(
            f"| {label} | {n} | {' '.join(f'{h} {k}' for h, k in hands.most_common()) or '-'} "
            f"| {_share(opposing, n)}{'*' if miss and opposing < OPPOSING_TARGET * n else ''} "
            f"| {_share(sum(bool(refusal(row)) for row in group), n)} "
            f"| {_share(sum(map(tipped, group)), n)} "
            f"| {_share(better, n)}{'*' if miss and better < NO_WORSE_TARGET * n else ''} "
            f"| {_share(flagged, n)} "
            f"| {fmt(_median([value(row, 'taxels_in_contact') for row in group]), 0)} |"
        )
    lines += [
        "",
        "## Shape per stage",
        "",
        "Medians over the object's finished trials of each trial's median deviation from the "
        "true surface, its Chamfer distance (mm) and F-score at 5 mm; `selected` is the stage "
        "the estimator selected.",
        "",
        "| object | finished | deviation (mm): S0 / S1 / S2 / selected "
        "| Chamfer (mm): S0 / S2 / selected | F-score 5 mm: S0 / S2 / selected |",
        "|---|---|---|---|---|",
    ]
    for label, group in by_object.items():
        done = [row for row in group if finished(row)]
        lines.append(
            f"| {label} | {len(done)} "
            f"| {_stage_cells(done, 'deviation_median_mm', (0, 1, 2))} "
            f"| {_stage_cells(done, 'chamfer_mm', (0, 2))} "
            f"| {_stage_cells(done, 'fscore_5mm', (0, 2))} |"
        )
    lines += kind_lines(rows)
    lines += model_lines(rows)
    lines += taxonomy_lines(by_object)
    lines += refusal_lines(rows)
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n")
    figure = objects_figure(by_object, out_dir / "objects.png", estimator)
    return [csv_path, figure, report_path]


def model_lines(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The model files of the trials that wrote one: how many have every stage's mesh
    closed, and how many have the selected stage's mesh within
    :data:`MESH_CHAMFER_FACTOR` of its points' Chamfer distance (with the median and the
    largest ratio)."""
    made = [row for row in rows if "model_watertight" in row]
    closed = sum(bool(row["model_watertight"]) for row in made)
    ratios = np.asarray(
        [selected_value(row, "mesh_chamfer_mm") / selected_value(row, "chamfer_mm") for row in made]
    )
    ratios = ratios[np.isfinite(ratios)]
    within = int(np.sum(ratios <= MESH_CHAMFER_FACTOR))
    largest = fmt(float(ratios.max()), 2) if ratios.size else "-"
    return [
        "",
        "## The model files",
        "",
        f"Trials that wrote a model (`model_stage{{k}}.obj`). Targets: every stage's mesh "
        f"closed in at least {100 * WATERTIGHT_TARGET:.0f} % of them; the selected stage's "
        f"mesh within {100 * (MESH_CHAMFER_FACTOR - 1):.0f} % of its points' Chamfer distance "
        "to the truth.",
        "",
        "| trials with a model | every mesh closed "
        f"| mesh Chamfer within {100 * (MESH_CHAMFER_FACTOR - 1):.0f} % of the points' "
        "| mesh / points: median, largest |",
        "|---|---|---|---|",
        f"| {len(made)} | {_share(closed, len(made))} | {_share(within, ratios.size)} "
        f"| {fmt(_median(ratios), 2)}, {largest} |",
    ]


def _stage_cells(rows: Sequence[Mapping[str, Any]], metric: str, stages: Sequence[int]) -> str:
    """The medians over ``rows`` of ``metric`` at each of ``stages`` and at the selected
    stage, ``" / "``-separated."""
    values = [_median([value(row, f"stage{k}_{metric}") for row in rows]) for k in stages]
    values.append(_median([selected_value(row, metric) for row in rows]))
    return " / ".join(fmt(v, 2) for v in values)


def part_of(row: Mapping[str, Any], scans: Sequence[str]) -> str:
    """``catalogue``, or for a scan (``scans``: their labels in name order) ``tune`` (even
    positions) or ``check`` (odd): the halves a rule is tuned and checked on."""
    label = row["params"]["label"]
    return ("tune", "check")[scans.index(label) % 2] if label in scans else "catalogue"


def kind_lines(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The trials per part and per the kind of symmetry that describes the object as it
    lies (:func:`pipeline.symmetry.scoring.true_kind`), with how many lay on their side."""
    scans = sorted(
        {
            row["params"]["label"]
            for row in rows
            if row["params"].get("object", row["params"]["label"]) != row["params"]["label"]
        }
    )
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault((part_of(row, scans), str(row.get("true_kind") or "-")), []).append(row)
    lines = [
        "",
        "## By the kind of symmetry as the object lies",
        "",
        "The object's true kind in its rest pose (`axis`: a body of revolution, standing or "
        "lying; `vertical-plane`: a vertical mirror plane; `plane`: only mirror planes that "
        "lean); 'lying': trials whose rest pose did not stand the object on its "
        "base or top. Angle error: the selected stage's plane against the nearest true "
        "symmetry (median, deg). Scans: the tune half (even positions in name order) and the "
        "check half (odd).",
        "",
        "| part | true kind | trials | lying | opposing contacts | no worse than vision "
        "| selected deviation (mm) | angle error S0 / selected (deg) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (part, kind), group in sorted(groups.items()):
        n = len(group)
        done = [row for row in group if finished(row)]
        angles = (
            _median([value(row, "stage0_symmetry_angle_error_deg") for row in done]),
            _median([selected_value(row, "symmetry_angle_error_deg") for row in done]),
        )
        lines.append(
            f"| {part} | {kind} | {n} "
            f"| {sum(row.get('rest_keeps_vertical') is False for row in group)} "
            f"| {_share(sum(bool(row.get('opposing_contacts')) for row in group), n)} "
            f"| {_share(sum(map(no_worse, group)), n)} "
            f"| {fmt(_median([selected_deviation(row) for row in done]), 2)} "
            f"| {fmt(angles[0], 1)} / {fmt(angles[1], 1)} |"
        )
    return lines


def taxonomy_lines(by_object: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """Where the trials that did not end fused and no worse than vision failed, per object
    (:func:`failure_stage`), and the first reason of each."""
    lines = [
        "",
        "## Where the failed trials failed",
        "",
        "segmentation: no object cloud; plane: no symmetry plane; planner: no hand's grasp, or "
        "the hand could not execute it; contact: the grasp touched one side only or nothing, "
        "so nothing was fused; estimator: fused, but worse than vision; raised: an exception.",
        "",
        "| object | " + " | ".join(TAXONOMY) + " | first reason |",
        "|---|" + "---|" * (len(TAXONOMY) + 1),
    ]
    totals: Counter[str] = Counter()
    for label, group in by_object.items():
        stages = Counter(s for row in group if (s := failure_stage(row)) is not None)
        if not stages:
            continue
        totals.update(stages)
        first = next(row for row in group if failure_stage(row) is not None)
        reason = first.get("error") or first.get("failed") or _estimator_reason(first)
        lines.append(
            f"| {label} | "
            + " | ".join(str(stages.get(s, 0) or "") for s in TAXONOMY)
            + f" | `{first['key']}`: {reason} |"
        )
    lines.append("| all | " + " | ".join(str(totals.get(s, 0)) for s in TAXONOMY) + " | |")
    return lines


def _estimator_reason(row: Mapping[str, Any]) -> str:
    return (
        f"selected Stage {row.get('selected_stage')} at {fmt(selected_deviation(row), 2)} mm, "
        f"Stage 0 at {fmt(value(row, 'stage0_deviation_median_mm'), 2)} mm "
        f"(status {row.get('status')})"
    )


def refusal_lines(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """Every distinct refusal, with the measurement the planners gave."""
    reasons = Counter(reason for row in rows if (reason := refusal(row)))
    if not reasons:
        return []
    lines = ["", f"## Refusals ({sum(reasons.values())})", ""]
    by_object = Counter(row["params"]["label"] for row in rows if refusal(row) is not None)
    lines += [f"- {label}: {count} trial(s)" for label, count in by_object.items()]
    lines += ["", "Reasons (the measurement that rules each hand out):", ""]
    lines += [f"- {count} x `{reason}`" for reason, count in reasons.most_common(20)]
    return lines


def objects_figure(
    by_object: Mapping[str, Sequence[Mapping[str, Any]]], out_path: Path, estimator: str
) -> Path:
    """``objects.png``: per object, the shares of trials with opposing contacts and fused
    no worse than vision, and the median deviation at Stage 0, Stage 2 and selected."""
    from pipeline.reports.figures import DotPanel, dot_figure

    labels = list(by_object)
    groups = [by_object[label] for label in labels]

    def share(test) -> list[float]:
        return [100.0 * sum(map(test, group)) / len(group) for group in groups]

    def median(metric) -> list[float]:
        return [_median([metric(row) for row in group if finished(row)]) for group in groups]

    panels = [
        DotPanel(
            "share of trials (%)",
            {
                "opposing contacts": share(lambda row: bool(row.get("opposing_contacts"))),
                "no worse than vision": share(no_worse),
            },
            (100.0 * OPPOSING_TARGET, 100.0 * NO_WORSE_TARGET),
        ),
        DotPanel(
            "median deviation (mm)",
            {
                "Stage 0": median(lambda row: value(row, "stage0_deviation_median_mm")),
                "Stage 2": median(lambda row: value(row, "stage2_deviation_median_mm")),
                "selected": median(selected_deviation),
            },
            (DEVIATION_TARGET_MM,),
        ),
    ]
    return dot_figure(labels, panels, out_path, title=f"Every object, estimator {estimator}")
