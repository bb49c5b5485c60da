"""Which kind of symmetry one view supports, and what each kind's completion is worth.

Every object (catalogue, and ``--scans DIR``'s ``*/textured.obj``) at 4 seeded yaws
(``--repeats N``; ``--quick``: one yaw of the salt cylinder and the CD drive), upright or in
the rest pose ``trial.rest`` gives it (``--rest``), is seen by the configured camera and
segmented, as a trial sees it, without a grasp. VC proposes its vertical plane and chooses,
as ``initialiser.vc.kind = "evidence"`` makes it (:mod:`pipeline.symmetry.kinds`), between it,
an axis (vertical, or of any direction) and a plane of any orientation. The view is
completed each way (the vertical plane's and the leaning plane's mirror images, the sweep
about the fitted axis, clipped at the table) and each completion's Chamfer distance to the
true surface is measured.

The report splits the views by the true kind of the object as it lies
(:func:`pipeline.symmetry.scoring.true_kind`) and the scans into the half the rules were
tuned on (even positions in name order) and the half they were checked on (odd positions).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.experiments import ExperimentOptions, SweepTask, explore
from pipeline.experiments.common import fmt, task_seed
from pipeline.experiments.init import yaws_deg
from pipeline.experiments.paper_tasks import paper_task, user_settings
from pipeline.experiments.rows import rest_fields
from pipeline.experiments.sweep import write_csv

NAME = "kinds"
DESCRIPTION = (
    "every object (catalogue, and --scans DIR) at 4 seeded yaws, one view: the kind of "
    "symmetry VC chooses by evidence, and the Chamfer distance of the vertical plane's, the "
    "axis' and the leaning plane's completions"
)
READS_SCANS = True
YAWS = 4
QUICK_OBJECTS = ("salt_cylinder", "cd_drive")


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    count = 1 if options.quick else (options.repeats or YAWS)
    found = explore.objects(dataclasses.replace(options, quick=False))
    if options.quick:
        found = [(label, name) for label, name in found if label in QUICK_OBJECTS]
    scans = sorted(label for label, name in found if name != label)
    result = []
    for index, yaw in enumerate(yaws_deg(options.seed, count)):
        for label, name in found:
            part = "catalogue" if name == label else ("tune", "check")[scans.index(label) % 2]
            key = f"{label}/yaw{index:02d}"
            params = {
                "object": name,
                "label": label,
                "part": part,
                "init": "vc",
                "gripper": "auto",
                "estimator": "mirror-only",
                "estimator_params": {},
                "paper_grasp": False,
                "yaw_deg": float(yaw),
                "seed": task_seed(options.seed, key),
                "overrides": ['initialiser.vc.kind="vertical-plane"'],
                "config": user_settings(options),
            }
            result.append(paper_task(key, params))
    return result


def run_one(params: Mapping[str, Any]) -> dict[str, Any]:
    """View, segment, choose the kind and score both completions of one task."""
    from pipeline.catalogue.rest import scene_object
    from pipeline.experiments.common import plugin_registry
    from pipeline.experiments.paper_tasks import trial_config
    from pipeline.metrics import mesh_deviation
    from pipeline.metrics.evaluation import GroundTruth, shape_scores
    from pipeline.symmetry.axis_fit import tilt_deg
    from pipeline.symmetry.kinds import complete, free_space_share, vc_kind
    from pipeline.symmetry.plane_search import table_top
    from pipeline.symmetry.scoring import symmetry_errors, true_kind
    from pipeline.symmetry.truth_file import true_symmetries
    from pipeline.types import SceneSetup, Symmetry

    registry = plugin_registry()
    config = trial_config(params)
    settings = config.trial
    obj = scene_object(settings)
    setup = SceneSetup(
        obj, settings.x_m, settings.y_m, float(np.radians(settings.yaw_deg)), settings.seed
    )
    world = config.create(registry, "world")
    try:
        world.load_scene(setup)
        pose = world.object_pose()
        observation = config.create(registry, "sensor").observe(world)
    finally:
        world.close()
    cloud = config.create(registry, "segmenter").segment(observation)
    # VC's vertical planes, then its choice of kind as `kind = "evidence"` makes it, kept
    # whole: the level choice, the axis fit and the best plane of any orientation.
    init = config.create(registry, "initialiser").propose(cloud, observation)
    vc = config.stage_params("initialiser")
    choice = vc_kind(cloud.points, observation, init.plane, vc)
    T = pose.transform
    truths = tuple(s.transformed(T) for s in true_symmetries(obj))
    vertices = np.asarray(obj.mesh.vertices) @ T[:3, :3].T + T[:3, 3]
    truth = GroundTruth(vertices, np.asarray(obj.mesh.faces), obj.symmetry, None, T[:2, 3])
    centre = vertices.min(axis=0) / 2.0 + vertices.max(axis=0) / 2.0
    # A view whose vertical planes VC rejects proposes a leaning plane or nothing.
    rejected = init.status != "ok"
    level = Symmetry.from_plane(init.plane) if rejected else choice.level
    chosen = level if rejected and choice.symmetry.kind != "plane" else choice.symmetry
    assert level is not None
    row: dict[str, Any] = {
        "label": params["label"],
        "part": params["part"],
        **rest_fields(None if obj.rest is None else obj.rest.to_json()),
        "true_kind": true_kind(truths),
        "chosen_kind": chosen.kind,
        "level_kind": level.kind,
        "status": init.status,
        **{f"score_{kind}": value for kind, value in choice.scores.items()},
    }
    for name, value in symmetry_errors(chosen, truths, centre).items():
        row[f"chosen_{name}"] = value
    for name, value in symmetry_errors(level, truths, centre).items():
        row[f"level_{name}"] = value
    completions = {"vertical-plane": Symmetry.from_plane(init.plane)}
    if choice.axis_fit is not None:
        row["profile_rms_mm"] = choice.axis_fit.profile_rms_m * 1e3
    if choice.tilted_fit is not None:
        row["tilted_profile_rms_mm"] = choice.tilted_fit.profile_rms_m * 1e3
    if choice.axis is not None:
        row["axis_tilt_deg"] = tilt_deg(choice.axis)
        completions["axis"] = choice.axis
    if choice.plane_fit is not None:
        completions["plane"] = choice.plane_fit.symmetry
    table_z = table_top(cloud.points, observation)
    for kind, symmetry in completions.items():
        model = complete(cloud.points, symmetry, table_z)
        row[f"free_space_{kind}"] = free_space_share(model, observation, vc.tolerance_m, table_z)
        distances, _ = mesh_deviation(model, truth.vertices, truth.faces)
        row[f"chamfer_{kind}_mm"] = shape_scores(model, distances, truth)["chamfer_mm"]
        for name, value in symmetry_errors(symmetry, truths, centre).items():
            row[f"{kind}_{name}"] = value
    return row


def _median(rows: Sequence[Mapping[str, Any]], key: str) -> str:
    values = [row[key] for row in rows if isinstance(row.get(key), int | float)]
    return fmt(float(np.median(values))) if values else "-"


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv`` and ``report.md``: the kind chosen and the completions' Chamfer
    distances per true kind and part, then per object."""
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    done = [row for row in rows if "error" not in row and not row.get("failed")]
    lines = [
        "# The kind of symmetry one view supports",
        "",
        f"{len(done)} of {len(rows)} views ran. True kind: of the object as it lies "
        "(`pipeline.symmetry.scoring.true_kind`); pose 'lying': views of an object not "
        "standing on its base or top. Chamfer distances in mm (medians) of the completions "
        "by VC's vertical plane, the axis (of any direction when one was a candidate, else "
        "the vertical fit), the best plane of any orientation, and the kind VC chose by "
        "evidence; 'axis wins' the share of views whose axis completion is closer to the "
        "truth than the vertical plane's. Angle errors (deg, medians) of the proposal "
        "against the nearest true symmetry: 'level' choosing between the vertical plane and "
        "the vertical axis alone, 'chosen' with planes and axes of any orientation.",
        "",
        "| part | true kind | pose | views | axis chosen | leaning plane chosen "
        "| Chamfer vertical plane | Chamfer axis | Chamfer any plane | Chamfer chosen "
        "| axis wins | angle error: level / chosen |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in done:
        row["chamfer_chosen_mm"] = row.get(f"chamfer_{row['chosen_kind']}_mm")
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for row in done:
        pose = "lying" if row.get("rest_keeps_vertical") is False else "upright"
        groups.setdefault((row["part"], row["true_kind"], pose), []).append(row)
    for (part, kind, pose), group in sorted(groups.items()):
        n = len(group)
        wins = sum(
            row.get("chamfer_axis_mm", math.inf) < row["chamfer_vertical-plane_mm"] for row in group
        )
        lines.append(
            f"| {part} | {kind} | {pose} | {n} "
            f"| {_count(group, 'axis')}/{n} | {_count(group, 'plane')}/{n} "
            f"| {_median(group, 'chamfer_vertical-plane_mm')} "
            f"| {_median(group, 'chamfer_axis_mm')} | {_median(group, 'chamfer_plane_mm')} "
            f"| {_median(group, 'chamfer_chosen_mm')} | {wins}/{n} "
            f"| {_median(group, 'level_symmetry_angle_error_deg')} "
            f"/ {_median(group, 'chosen_symmetry_angle_error_deg')} |"
        )
    lines += [
        "",
        "| object | part | true kind | views | lying | axis chosen | leaning plane chosen "
        "| profile RMS mm | Chamfer vertical plane | Chamfer axis | Chamfer any plane "
        "| angle error: level / chosen |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    by_object: dict[str, list[dict]] = {}
    for row in done:
        by_object.setdefault(row["label"], []).append(row)
    for label, group in sorted(by_object.items()):
        first, n = group[0], len(group)
        kinds = sorted({row["true_kind"] for row in group})
        lines.append(
            f"| {label} | {first['part']} | {', '.join(kinds)} | {n} "
            f"| {sum(row.get('rest_keeps_vertical') is False for row in group)} "
            f"| {_count(group, 'axis')}/{n} | {_count(group, 'plane')}/{n} "
            f"| {_median(group, 'profile_rms_mm')} "
            f"| {_median(group, 'chamfer_vertical-plane_mm')} "
            f"| {_median(group, 'chamfer_axis_mm')} | {_median(group, 'chamfer_plane_mm')} "
            f"| {_median(group, 'level_symmetry_angle_error_deg')} "
            f"/ {_median(group, 'chosen_symmetry_angle_error_deg')} |"
        )
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n")
    return [csv_path, report_path]


def _count(rows: Sequence[Mapping[str, Any]], kind: str) -> int:
    return sum(row["chosen_kind"] == kind for row in rows)
