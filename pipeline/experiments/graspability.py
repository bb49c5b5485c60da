"""Grasp success as the model's score: does fusing the touch make a model a robot grasps
better with?

The trials are those of ``symfuse sweep objects`` (:mod:`.objects`: every catalogue
object, and every ``DIR/*/textured.obj`` of ``--scans DIR``, at seeded yaws, one full
trial each, the same seeds and keys). After a trial, the trial's hand and planner plan
:data:`GRASPS` grasps (the planner's best, :meth:`~pipeline.stages.GraspPlanner.alternatives`)
on each of three models (:data:`MODELS`):

- ``stage0``: Stage 0's watertight mesh (vision and the initial plane);
- ``fused``: the mesh of the stage the estimator selected;
- ``true``: the true mesh (the ceiling), with the true vertical mirror plane nearest the
  fused model's (:func:`true_plane`; the fused model's own where the object has none: the
  planner completes a cloud by its plane).

Each is given to the planner as points drawn evenly on its surface but the face it stands
on, as many as the selected stage's completed cloud. A stage's mesh is the one the trial
wrote (:func:`stage_meshes`), its completed cloud closed into a solid: the cloud itself has
holes where neither the camera nor its mirror image saw (a ball's sides below its
equator), and a planner that finds no surface there grasps where there is one, above the
equator, where a squeeze pushes the ball out. A trial without a mesh gives the completed
cloud (``planned_on``).

Each model comes with the plane it is symmetric about (a completed cloud, and its mesh,
mirror onto themselves): a stage's plane moved by its bias
(:func:`~pipeline.metrics.plane_after_bias`; the plane the estimator holds is the one
before the bias, and mirroring a fused model through it adds a copy turned by twice the
bias's yaw, too wide for the jaws). Each is moved by the object's true motion from where
the model was scored (the object after the trial's grasps) to its resting pose, its turn
about the vertical and its shift at the fused model's centroid (:func:`planar_motion`:
not the tilt the pads gave the held object, which the upright models never had), so that
the three differ by their shape and by where the estimate put it, not by the trial's
grasp. Each grasp is executed on the
true object in a freshly built scene (the object at its resting pose, every attempt
alike), then lifted :data:`LIFT_M` and held :data:`HOLD_S` (:meth:`World.lift
<pipeline.stages.World.lift>`): it succeeds when the object is still held
(:func:`pipeline.sim.grasp_sequence.held`: it rose with the hand to within the slip
allowance and at least two fingers touch it). A model's success in a trial is its held
grasps over :data:`GRASPS`: a grasp the planner could not offer on the model, or the
hand could not execute, counts as failed.

Rows: the trial's row (:mod:`.paper_trial`: Chamfer, F-score and IoU per stage) and per
model ``<model>_plans``, ``<model>_executed``, ``<model>_held`` (counts),
``<model>_success`` (held / :data:`GRASPS`) and ``<model>_first_miss`` (the first attempt
that was not held and why); ``fused_stage``; ``planned_on`` (``"mesh"``, or ``"cloud"``
when the trial wrote no mesh). A trial that stopped before an estimate
has no model and no grasp counts (the report counts it apart).
"""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.experiments import ExperimentOptions, SweepTask, objects
from pipeline.experiments.common import fmt, plugin_registry
from pipeline.experiments.paper_tasks import trial_config, user_settings
from pipeline.experiments.paper_trial import paper_trial
from pipeline.experiments.sweep import write_csv

if TYPE_CHECKING:
    from pipeline.run.trial import TrialRecord
    from pipeline.types import GraspPlan, ObjectPose, StageEstimate, Symmetry, SymmetryPlane

NAME = "graspability"
DESCRIPTION = (
    "every object (catalogue, and --scans DIR) at 10 seeded yaws: 5 grasps planned on "
    "Stage 0's, the fused and the true model, each lifted 10 cm and held 2 s"
)
#: The experiment reads the sweep's ``--scans`` folder.
READS_SCANS = True
#: Grasps planned and executed per model and trial.
GRASPS = 5
#: How high a grasp lifts the object (m), and how long it holds it there (s).
LIFT_M = 0.10
HOLD_S = 2.0
#: The models each trial's grasps are planned on, in report order.
MODELS = ("stage0", "fused", "true")
MODEL_LABELS = {"stage0": "Stage 0", "fused": "fused", "true": "true mesh"}
#: The claims checked: fused at least Stage 0 on average, and within this many
#: percentage points of the true mesh.
CEILING_GAP_POINTS = 10.0
#: How far from upright a true mirror plane or rotation axis may lean and still give the
#: true mesh's vertical plane (deg): a scanned mesh rests a few degrees off its axes.
UPRIGHT_DEG = 10.0


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    """The trials of ``sweep objects`` (same keys and seeds), each with the grasps to make,
    yaw by yaw and, within a yaw, the objects in a random order (seeded by the sweep's
    seed): a sweep stopped early has graded a random sample of the objects, catalogue and
    scans alike, rather than the first of the list.

    Raises:
        ConfigError: the configured world cannot lift (:meth:`World.lift
            <pipeline.stages.World.lift>` not implemented), checked before any trial runs.
    """
    from pipeline.config import load_config
    from pipeline.errors import ConfigError
    from pipeline.stages import World

    world = load_config(plugin_registry(), settings=user_settings(options)).choices["world"]
    if plugin_registry().get("world", world).cls.lift is World.lift:
        raise ConfigError(f"world '{world}' cannot lift: sweep graspability needs World.lift")
    trials = objects.tasks(options)
    rng = np.random.default_rng(options.seed)
    ordered = []
    for yaw in dict.fromkeys(task.key.rpartition("/")[2] for task in trials):
        group = [task for task in trials if task.key.rpartition("/")[2] == yaw]
        ordered += [group[i] for i in rng.permutation(len(group))]
    return [
        SweepTask(task.key, {**task.params, "grasps": GRASPS}, task.settings) for task in ordered
    ]


def run_one(params: dict) -> dict[str, Any]:
    with paper_trial(params) as (row, record):
        if record is not None:
            row.update(grasp_models(params, record))
    return row


# ---------------------------------------------------------------- models and attempts


@dataclass(frozen=True)
class PlanningModel:
    """What the planner is given for one model: points (frame R, the object at its resting
    pose), their mirror plane, and what the points were drawn from: ``"mesh"`` (a
    watertight surface) or ``"cloud"`` (a stage's completed cloud, when the trial wrote no
    mesh)."""

    points: np.ndarray
    plane: SymmetryPlane
    source: str


def _pose(entry: Mapping[str, Any]) -> ObjectPose:
    from pipeline.types import ObjectPose

    return ObjectPose(np.asarray(entry["position"]), np.asarray(entry["quaternion_xyzw"]))


def planar_motion(motion: np.ndarray, pivot_m: np.ndarray) -> np.ndarray:
    """The planar part of the rigid ``motion`` (4x4, frame R): the turn about the vertical
    nearest its rotation (the yaw of ``R`` that maximises ``trace(R_z^T R)``), and the
    shift that moves ``pivot_m`` where ``motion`` does. A held object tilts in the pads by
    a degree or two (a tall box squeezed above its middle); the models, upright like the
    bias that placed them (docs/method.md §1), are carried by the turn and the shift
    alone: carried by the tilt too, a 17 cm box comes out leaning 5 mm at its top, and
    mirrored through its vertical plane by the planner, 10 mm wider there."""
    from pipeline.geometry.poses import rotation_z

    rotation = motion[:3, :3]
    yaw = math.atan2(rotation[1, 0] - rotation[0, 1], rotation[0, 0] + rotation[1, 1])
    planar = np.eye(4)
    planar[:3, :3] = rotation_z(yaw)
    planar[:3, 3] = rotation @ pivot_m + motion[:3, 3] - planar[:3, :3] @ pivot_m
    return planar


def moved_plane(plane: SymmetryPlane, motion: np.ndarray) -> SymmetryPlane:
    """``plane`` carried by the rigid ``motion`` (4x4, frame R), its normal kept
    horizontal (exactly so for a :func:`planar_motion`)."""
    from pipeline.types import SymmetryPlane

    normal = motion[:3, :3] @ plane.normal
    point = motion[:3, :3] @ (plane.normal * plane.offset_m) + motion[:3, 3]
    return SymmetryPlane.from_normal(normal[:2], float(normal[:2] @ point[:2]))


def planning_models(
    record: TrialRecord, obj: Any, resting: ObjectPose, seed: int
) -> dict[str, PlanningModel]:
    """:data:`MODELS` for the planner, the object at ``resting`` (see the module doc)."""
    from pipeline.metrics import plane_after_bias
    from pipeline.metrics.shape_scores import sample_surface
    from pipeline.run.trial import ground_truth

    result = record.result
    scored_at = _pose(record.document["object_pose_after"])
    motion = planar_motion(
        resting.transform @ np.linalg.inv(scored_at.transform),
        result.selected.completed.mean(axis=0),
    )

    def moved(points: np.ndarray) -> np.ndarray:
        return points @ motion[:3, :3].T + motion[:3, 3]

    count = len(result.selected.completed)
    meshes = stage_meshes(record)

    def model(stage: StageEstimate) -> PlanningModel:
        plane = moved_plane(plane_after_bias(stage.plane, stage.bias), motion)
        mesh = meshes.get(stage.stage) if meshes else None
        if mesh is None:
            return PlanningModel(moved(stage.completed), plane, "cloud")
        # Its surface but the face it stands on, sampled as the true mesh's is.
        return PlanningModel(moved(sample_surface(*mesh, count, seed=seed)), plane, "mesh")

    stage0, fused = model(result.stages[0]), model(result.selected)
    T = resting.transform
    # The true surface but the face it stands on, which no model has either.
    samples = sample_surface(obj.mesh.vertices, obj.mesh.faces, count, seed=seed)
    truth = ground_truth(obj, resting, resting, None)
    plane = truth.plane
    if plane is None:
        centre = (truth.vertices.min(axis=0) + truth.vertices.max(axis=0)) / 2.0
        plane = true_plane(truth.symmetries, fused.plane, centre)
    return {
        "stage0": stage0,
        "fused": fused,
        "true": PlanningModel(samples @ T[:3, :3].T + T[:3, 3], plane or fused.plane, "mesh"),
    }


def stage_meshes(record: TrialRecord) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Each stage's watertight mesh the trial wrote (``model_stage{k}.obj``, docs/formats.md)
    as vertices (frame R, where the model was scored) and faces; empty when the trial wrote
    no model (``result.json``'s ``model`` entry says why)."""
    import trimesh

    entry = record.document.get("model", {})
    if entry.get("status") != "ok":
        return {}
    T = np.asarray(entry["T_robot_object"], dtype=float)
    meshes = {}
    for stage, name in entry["files"]["stages"].items():
        mesh = trimesh.load(record.out_dir / name, force="mesh", process=False)
        vertices = np.asarray(mesh.vertices, dtype=float) @ T[:3, :3].T + T[:3, 3]
        meshes[int(stage)] = (vertices, np.asarray(mesh.faces))
    return meshes


def true_plane(
    symmetries: Sequence[Symmetry], near: SymmetryPlane, centre_m: np.ndarray
) -> SymmetryPlane | None:
    """The object's true vertical mirror plane nearest ``near`` by angle, then by offset
    (:func:`pipeline.symmetry.scoring.pair_errors`, measured at ``centre_m``, frame R): a
    true plane whose normal lies within :data:`UPRIGHT_DEG` of horizontal, or the plane
    parallel to ``near`` through an axis within :data:`UPRIGHT_DEG` of vertical or through
    a sphere's centre (every plane containing them is a symmetry); None when the object
    has none of them (an asymmetric object, a lying body of revolution)."""
    from pipeline.symmetry.scoring import pair_errors, round_centre
    from pipeline.types import Symmetry, SymmetryPlane

    level = math.sin(math.radians(UPRIGHT_DEG))
    found = []
    centre = round_centre(symmetries)
    anchors = [] if centre is None else [centre]
    for truth in symmetries:
        if truth.is_plane and abs(truth.direction[2]) <= level:
            normal = truth.direction[:2]
            found.append(SymmetryPlane.from_normal(normal, float(normal @ truth.point_m[:2])))
        elif not truth.is_plane and abs(truth.direction[2]) >= math.cos(math.radians(UPRIGHT_DEG)):
            anchors.append(truth.point_m)
    normal = near.normal[:2]
    found += [SymmetryPlane.from_normal(normal, float(normal @ a[:2])) for a in anchors]
    if not found:
        return None
    estimate = Symmetry.from_plane(near)
    return min(
        found,
        key=lambda plane: pair_errors(estimate, Symmetry.from_plane(plane), centre_m),
    )


@dataclass(frozen=True)
class Attempt:
    """One grasp of a model on the true object: executed, held after the lift, and why
    not (empty when held)."""

    executed: bool
    held: bool
    reason: str


def attempt(world: Any, setup: Any, gripper: str, plan: GraspPlan) -> Attempt:
    """Build the scene afresh, grasp with ``plan``, lift and hold (module doc)."""
    world.load_scene(setup)
    world.add_hand(gripper)
    outcome = world.execute_grasp(plan)
    if not outcome.executed:
        return Attempt(False, False, f"not executed: {outcome.reason}")
    lifted = world.lift(LIFT_M, HOLD_S)
    if lifted.held:
        return Attempt(True, True, "")
    return Attempt(
        True,
        False,
        f"dropped: rose {round(1e3 * lifted.rise_m)} mm of {1e3 * LIFT_M:.0f}, "
        f"{lifted.fingers_touching} finger(s) touching",
    )


def grasp_models(params: Mapping[str, Any], record: TrialRecord) -> dict[str, Any]:
    """Plan ``params["grasps"]`` grasps on each model and execute each; the row fields
    (module doc)."""
    from pipeline.catalogue.rest import scene_object
    from pipeline.planning.hand_choice import create_planner
    from pipeline.types import Bias, PointCloud, SceneSetup, SymmetryInit

    config = trial_config(params)
    registry = plugin_registry()
    settings = config.trial
    document = record.document
    gripper = document["gripper"]
    planner = create_planner(config, registry, document["stages_used"]["planner"])
    obj = scene_object(settings)
    setup = SceneSetup(
        obj, settings.x_m, settings.y_m, float(np.radians(settings.yaw_deg)), settings.seed
    )
    camera = json.loads((record.out_dir / "camera.json").read_text())
    viewpoint = np.asarray(camera["T_robot_camera"])[:3, 3]
    count = int(params["grasps"])
    fields: dict[str, Any] = {"fused_stage": record.result.selected.stage}
    with contextlib.closing(config.create(registry, "world")) as world:
        world.load_scene(setup)
        resting = world.object_pose()
        spec = world.gripper_spec(gripper)
        models = planning_models(record, obj, resting, settings.seed)
        fields["planned_on"] = models["fused"].source
        for name, model in models.items():
            cloud = PointCloud(model.points, "robot", None, viewpoint)
            plans = planner.alternatives(cloud, SymmetryInit(model.plane, Bias()), spec)[:count]
            attempts = [attempt(world, setup, gripper, plan) for plan in plans]
            misses = [a.reason for a in attempts if not a.held]
            if len(plans) < count:
                misses.append(f"the planner offered {len(plans)} grasp(s) of {count}")
            held = sum(a.held for a in attempts)
            fields.update(
                {
                    f"{name}_plans": len(plans),
                    f"{name}_executed": sum(a.executed for a in attempts),
                    f"{name}_held": held,
                    f"{name}_success": held / count,
                    f"{name}_first_miss": misses[0] if misses else "",
                }
            )
    return fields


# ---------------------------------------------------------------- the report


def graded(row: Mapping[str, Any]) -> bool:
    """Whether the trial reached an estimate and its models were grasped."""
    return "error" not in row and f"{MODELS[0]}_success" in row


def mean_success(rows: Sequence[Mapping[str, Any]], model: str) -> float:
    """The mean over graded rows of ``model``'s success (%); NaN without any."""
    values = [float(row[f"{model}_success"]) for row in rows if graded(row)]
    return 100.0 * float(np.mean(values)) if values else math.nan


def _percent(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.0f} %"


def _median(rows: Sequence[Mapping[str, Any]], field: str) -> float:
    values = np.asarray([row.get(field, math.nan) for row in rows], dtype=float)
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else math.nan


def _shape_cells(rows: Sequence[Mapping[str, Any]], metric: str, digits: int) -> str:
    """Medians of ``metric`` of Stage 0 and of the selected stage over ``rows``."""
    stage0 = _median(rows, f"stage0_{metric}")
    chosen = np.asarray(
        [row.get(f"stage{row['fused_stage']}_{metric}", math.nan) for row in rows], dtype=float
    )
    chosen = chosen[np.isfinite(chosen)]
    fused = float(np.median(chosen)) if chosen.size else math.nan
    return f"{fmt(stage0, digits)} / {fmt(fused, digits)}"


def claims(rows: Sequence[Mapping[str, Any]]) -> dict[str, bool]:
    """The two claims over every graded trial (module doc)."""
    stage0, fused, true = (mean_success(rows, model) for model in MODELS)
    return {
        "fused >= Stage 0": bool(fused >= stage0),
        f"fused within {CEILING_GAP_POINTS:g} points of the true mesh": bool(
            true - fused <= CEILING_GAP_POINTS
        ),
    }


def summary_lines(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The headline table: mean success per model over the graded trials, the shares of
    trials where fusion lost grasps, and the claims."""
    done = [row for row in rows if graded(row)]
    worse = sum(row["fused_success"] < row["stage0_success"] for row in done)
    better = sum(row["fused_success"] > row["stage0_success"] for row in done)
    checks = claims(rows) if done else {}
    return [
        "| trials | graded | success: Stage 0 | fused | true mesh | fused better / worse "
        "than Stage 0 (trials) |",
        "|---|---|---|---|---|---|",
        f"| {len(rows)} | {len(done)} | "
        + " | ".join(_percent(mean_success(rows, m)) for m in MODELS)
        + f" | {better} / {worse} |",
        "",
        *(f"- {claim}: {'met' if ok else 'NOT met'}" for claim, ok in checks.items()),
    ]


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv``, ``graspability.png`` and ``report.md`` (see the module doc)."""
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    by_object: dict[str, list[Mapping[str, Any]]] = {}
    for row in rows:
        by_object.setdefault(row["params"]["label"], []).append(row)
    lines = [
        "# Grasp success per model",
        "",
        f"Each trial's hand plans {GRASPS} grasps (its planner's best) on each model's "
        "surface: Stage 0's mesh, the fused (selected) stage's, and the true mesh (the "
        "ceiling). Each grasp is executed on the true object, from its resting pose every "
        f"time, lifted {100 * LIFT_M:.0f} cm and held {HOLD_S:g} s; it succeeds when the "
        "object rose with the hand (within the slip allowance) and lies between at least "
        f"two fingers. Success: held grasps over {GRASPS}, a grasp the planner did not "
        "offer counted as failed; means over the trials that reached an estimate (graded).",
        "",
        *summary_lines(rows),
        "",
        "## Per object",
        "",
        "Success: mean over the object's graded trials. Chamfer (mm), F-score at 5 mm and "
        "IoU of the completed cloud: medians, Stage 0 / fused.",
        "",
        "| object | graded / trials | Stage 0 | fused | true mesh | Chamfer (mm) "
        "| F-score 5 mm | IoU |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, group in by_object.items():
        done = [row for row in group if graded(row)]
        successes = " | ".join(_percent(mean_success(group, m)) for m in MODELS)
        lines.append(
            f"| {label} | {len(done)} / {len(group)} | {successes} "
            f"| {_shape_cells(done, 'chamfer_mm', 1)} | {_shape_cells(done, 'fscore_5mm', 2)} "
            f"| {_shape_cells(done, 'iou', 2)} |"
        )
    lines += miss_lines(rows)
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n")
    figure = success_figure(by_object, out_dir / "graspability.png")
    return [csv_path, figure, report_path]


def miss_lines(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The trials without an estimate, and each model's first missed grasp per trial."""
    lines = []
    ungraded = [row for row in rows if not graded(row)]
    if ungraded:
        lines += ["", f"## Trials without an estimate ({len(ungraded)})", ""]
        lines += [
            f"- `{row['key']}`: {row.get('error') or row.get('failed') or '-'}"
            for row in ungraded[:20]
        ]
    missed = [
        (row["key"], model, row[f"{model}_first_miss"])
        for row in rows
        if graded(row)
        for model in MODELS
        if row[f"{model}_first_miss"]
    ]
    if missed:
        lines += ["", f"## First missed grasp per trial and model ({len(missed)})", ""]
        lines += [f"- `{key}` {MODEL_LABELS[model]}: {why}" for key, model, why in missed[:40]]
        if len(missed) > 40:
            lines.append(f"- ... and {len(missed) - 40} more (see results.csv)")
    return lines


def success_figure(by_object: Mapping[str, Sequence[Mapping[str, Any]]], out_path: Path) -> Path:
    """``graspability.png``: grasp success per model (bars), per object and over all."""
    from pipeline.reports.figures import BarGroups, bar_figure

    labels = [*by_object, "all"]
    groups = [*by_object.values(), [row for group in by_object.values() for row in group]]
    series = {
        MODEL_LABELS[model]: [mean_success(group, model) for group in groups] for model in MODELS
    }
    return bar_figure(
        BarGroups(labels, series, "grasp success (%)"),
        out_path,
        title=f"Grasps lifted {100 * LIFT_M:.0f} cm and held {HOLD_S:g} s, per model",
    )
