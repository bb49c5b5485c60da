"""Which kind of symmetry one view supports, and what each kind's completion is worth.

Every object (catalogue, and ``--scans DIR``'s ``*/textured.obj``) standing at 4 seeded
yaws (``--repeats N``; ``--quick``: one yaw of the salt cylinder and the CD drive) is seen by
the configured camera and segmented, as a trial sees it, without a grasp. VC proposes its
vertical plane and chooses between it and a vertical axis by evidence
(``initialiser.vc.kind = "evidence"``, :mod:`pipeline.symmetry.kinds`). The view is completed
both ways, by the plane's mirror image and by sweeping it about the fitted axis, and each
completion's Chamfer distance to the true surface is measured.

The report splits the objects by their true kind (a body of revolution standing upright
has a vertical axis among its true symmetries, :mod:`pipeline.symmetry.truth_file`, and a
sphere several axes) and the
scans into the half the rule was tuned on (even positions in name order) and the half it
was checked on (odd positions).
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
    "symmetry VC chooses by evidence, and the Chamfer distance of the plane's and the axis' "
    "completions"
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
                "overrides": ['initialiser.vc.kind="evidence"'],
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
    from pipeline.symmetry.axis_fit import fit_axis
    from pipeline.symmetry.kinds import complete, free_space_share
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
    init = config.create(registry, "initialiser").propose(cloud, observation)
    T = pose.transform
    truths = tuple(s.transformed(T) for s in true_symmetries(obj))
    vertices = np.asarray(obj.mesh.vertices) @ T[:3, :3].T + T[:3, 3]
    truth = GroundTruth(vertices, np.asarray(obj.mesh.faces), obj.symmetry, None, T[:2, 3])
    centre = vertices.min(axis=0) / 2.0 + vertices.max(axis=0) / 2.0
    row: dict[str, Any] = {
        "label": params["label"],
        "part": params["part"],
        **rest_fields(None if obj.rest is None else obj.rest.to_json()),
        "true_kind": true_kind(truths),
        "chosen_kind": init.kind,
        "status": init.status,
        **{f"score_{kind}": value for kind, value in init.kind_scores.items()},
    }
    for name, value in symmetry_errors(init.proposed, truths, centre).items():
        row[f"chosen_{name}"] = value
    plane = Symmetry.from_plane(init.hypotheses[0].plane) if init.hypotheses else init.proposed
    fit = fit_axis(cloud.points)
    completions = {"vertical-plane": plane}
    if fit is not None:
        row["profile_rms_mm"] = fit.profile_rms_m * 1e3
        completions["axis"] = fit.axis
    tolerance = config.stage_params("initialiser").tolerance_m
    for kind, symmetry in completions.items():
        model = complete(cloud.points, symmetry)
        row[f"free_space_{kind}"] = free_space_share(model, observation, tolerance)
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
        f"{len(done)} of {len(rows)} views ran. Chamfer distances in mm (medians); 'chosen' is "
        "the completion of the kind VC chose by evidence; 'axis wins' the share of views whose "
        "axis completion is closer to the truth than the plane's.",
        "",
        "| part | true kind | views | axis chosen | Chamfer plane | Chamfer axis "
        "| Chamfer chosen | axis wins |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in done:
        chosen = row.get(f"chamfer_{row['chosen_kind']}_mm")
        row["chamfer_chosen_mm"] = chosen
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in done:
        groups.setdefault((row["part"], row["true_kind"]), []).append(row)
    for (part, kind), group in sorted(groups.items()):
        chosen = sum(row["chosen_kind"] == "axis" for row in group)
        wins = sum(
            row.get("chamfer_axis_mm", math.inf) < row["chamfer_vertical-plane_mm"] for row in group
        )
        lines.append(
            f"| {part} | {kind} | {len(group)} | {chosen}/{len(group)} "
            f"| {_median(group, 'chamfer_vertical-plane_mm')} "
            f"| {_median(group, 'chamfer_axis_mm')} "
            f"| {_median(group, 'chamfer_chosen_mm')} | {wins}/{len(group)} |"
        )
    lines += [
        "",
        "| object | part | true kind | views | axis chosen | profile RMS mm "
        "| Chamfer plane | Chamfer axis | proposal's angle error (deg) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    by_object: dict[str, list[dict]] = {}
    for row in done:
        by_object.setdefault(row["label"], []).append(row)
    for label, group in sorted(by_object.items()):
        first = group[0]
        chosen = sum(row["chosen_kind"] == "axis" for row in group)
        lines.append(
            f"| {label} | {first['part']} | {first['true_kind']} | {len(group)} "
            f"| {chosen}/{len(group)} | {_median(group, 'profile_rms_mm')} "
            f"| {_median(group, 'chamfer_vertical-plane_mm')} "
            f"| {_median(group, 'chamfer_axis_mm')} "
            f"| {_median(group, 'chosen_symmetry_angle_error_deg')} |"
        )
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n")
    return [csv_path, report_path]
