"""One full simulated grasp trial, from the camera to the evaluated estimate.

    world -> sensor -> segmenter -> initialiser.propose -> planner (and hand choice)
      -> grasp -> tactile -> initialiser.refine -> estimator -> evaluation

The configured world (a stage like the others, :class:`pipeline.stages.World`) builds the
scene; it is sensed before its hand is chosen (:mod:`pipeline.hand_choice`) among the hands
the world offers, and the chosen hand is then added to it.

Every file the trial writes goes into one output folder (see :data:`TRIAL_FILES`); the
stages are timed one by one, and the resolved config is written next to the results.

One module because it is the sequence above end to end: the simulation, the grasp-and-fuse
loop and the files and pictures they write share the trial's config, timer and record, so
reading it top to bottom is reading one trial.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .asset.files import write_model
from .camera_file import camera_to_json
from .catalogue import CatalogueObject, load_object
from .config import Config
from .errors import StageFailure, SymfuseError
from .estimation.map_params import regrasp_noise
from .evaluation import (
    GroundTruth,
    evaluate_stage,
    model_scores,
    object_motion,
    object_turn,
    opposing_contacts,
)
from .formats import (
    bias_to_json,
    contacts_to_json,
    estimate_to_json,
    plan_to_json,
    plane_to_json,
    selection_to_json,
    symmetry_to_json,
    write_cloud,
    write_completed_clouds,
    write_json,
)
from .hand_choice import HandChoice, choice_to_json, choose_grasp, create_planner, next_try
from .next_grasp import (
    MeasurementModel,
    NextHand,
    Uncertainty,
    choose_next_grasp,
    stop_reason,
    uncertainty,
)
from .registry import StageRegistry
from .runner import estimate
from .stages import World
from .symmetry.truth_file import true_symmetries
from .types import (
    Contacts,
    DepthObservation,
    EstimateResult,
    GraspPlan,
    ObjectPose,
    PointCloud,
    SceneSetup,
    SymmetryInit,
    SymmetryPlane,
)

#: The pictures a trial draws unless ``trial.pictures = false`` (VC adds ``vc_scores.png``).
PICTURE_FILES = ("rgb.png", "depth.png", "topdown.png", "deviation.png", "grasps.png")
#: The data every completed trial writes into its output folder.
TRIAL_FILES = (
    "depth.npy",
    "camera.json",
    "cloud.ply",
    "contacts.json",
    "completed_stage0.ply",
    "completed_stage1.ply",
    "completed_stage2.ply",
    "object_final.ply",
    "model.obj",
    "model_stage0.obj",
    "model_stage1.obj",
    "model_stage2.obj",
    "model_collision.obj",
    "model.urdf",
    "result.json",
    "config.toml",
)


@dataclass
class PhaseTimer:
    """Wall time per named phase, in seconds, in the order the phases ran."""

    seconds: dict[str, float] = field(default_factory=dict)

    @contextmanager
    def phase(self, name: str) -> Iterator[None]:
        started = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - started


@dataclass(frozen=True)
class TrialRecord:
    """What :func:`run_trial` returns: the estimate, its evaluation and the output folder."""

    out_dir: Path
    result: EstimateResult
    metrics: list[dict[str, Any]]
    timings: dict[str, float]
    document: dict[str, Any]


def pose_to_json(pose: ObjectPose) -> dict[str, Any]:
    return {
        "position": [float(v) for v in pose.position_m],
        "quaternion_xyzw": [float(v) for v in pose.quaternion_xyzw],
    }


def ground_truth(
    obj: CatalogueObject,
    pose_after: ObjectPose,
    pose_seen: ObjectPose,
    calibration_error: np.ndarray | None,
) -> GroundTruth:
    """The object's truth in frame R after the grasp.

    When the sensor knows its calibration error (:attr:`DepthObservation.calibration_error`)
    the truth also holds the bias the estimator should find: the motion from where the
    cloud put the object, ``calibration_error @ T_seen`` (``pose_seen``: the object when the
    camera saw it), to where it is after the grasp.
    """
    T = pose_after.transform
    cloud_motion = None
    if calibration_error is not None:
        cloud_motion = T @ np.linalg.inv(calibration_error @ pose_seen.transform)
    vertices = np.asarray(obj.mesh.vertices) @ T[:3, :3].T + T[:3, 3]
    plane, anchor = None, T[:3, 3]
    if obj.symmetry == "planar" and obj.symmetry_plane is not None:
        normal = T[:3, :3] @ obj.symmetry_plane.normal
        anchor = T[:3, 3] + T[:3, :3] @ (obj.symmetry_plane.normal * obj.symmetry_plane.offset_m)
        plane = SymmetryPlane.from_normal(normal[:2], float(normal[:2] @ anchor[:2]))
    dims = obj.dimensions_m
    return GroundTruth(
        vertices=vertices,
        faces=np.asarray(obj.mesh.faces),
        symmetry=obj.symmetry,
        plane=plane,
        # The object origin, or the true plane's point nearest it (a mesh's plane given
        # by the user need not pass through the centre of its bounding box).
        axis_xy_m=anchor[:2].copy(),
        thickness_m=dims.get("thickness") if obj.kind == "box" else None,
        diameter_m=dims.get("diameter") if obj.kind == "cylinder" else None,
        cloud_motion=cloud_motion,
        symmetries=tuple(s.transformed(T) for s in true_symmetries(obj)),
    )


def draw_pictures(
    out_dir: Path,
    config: Config,
    points: np.ndarray,
    init: SymmetryInit,
    result: EstimateResult,
    evaluated: list[tuple[dict[str, Any], np.ndarray]],
    truth: GroundTruth,
) -> None:
    """``deviation.png`` (Stages 0-2 over the true mesh), ``topdown.png`` (cloud and initial
    plane) and, when the initialiser ranked hypotheses, ``vc_scores.png``."""
    from .trial_pictures import (
        DeviationPanel,
        deviation_heatmap,
        plot_cloud_with_plane,
        plot_vc_scores,
    )

    name = config.trial.object
    panels = [
        DeviationPanel(f"Stage {stage.stage}", stage.completed, distances)
        for stage, (_, distances) in zip(result.stages, evaluated, strict=True)
    ]
    deviation_heatmap(
        panels,
        out_dir / "deviation.png",
        mesh=(truth.vertices, truth.faces),
        azimuth_rad=np.radians(-150.0),
        elevation_rad=np.radians(35.0),
        title=f"{name}: deviation from the true surface (3/4 view)",
    )
    plot_cloud_with_plane(
        points,
        init.plane,
        out_dir / "topdown.png",
        title=f"{name}: initial symmetry plane ({config.choices['initialiser']})",
    )
    if init.hypotheses:
        plot_vc_scores(init.hypotheses, points.mean(axis=0), out_dir / "vc_scores.png")


def draw_grasps(
    out_path: Path,
    name: str,
    result: EstimateResult,
    truth: GroundTruth,
    fused: Fused,
    document: dict[str, Any],
) -> None:
    """``grasps.png``: the object from above with every grasp's pads numbered, how it was
    chosen and by which hand, and the selected stage's median deviation after it; the grasp
    the trial stopped on without fusing it, where it was planned to touch."""
    from .figures import GraspMarks, grasps_figure

    marks = []
    for contacts, entry in zip(fused.contacts, document["grasps"], strict=True):
        stage = entry["selected_stage"]
        median_mm = 1e3 * entry["stages"][stage]["metrics"]["deviation_m"]["median"]
        chosen = f"{entry['chosen_by']['strategy']} ({entry['gripper']})"
        label = f"{chosen}, then {median_mm:.1f} mm (Stage {stage})"
        marks.append(GraspMarks(label, contacts.positions, contacts.pads))
    if unfused := document.get("unfused_grasp"):
        planned = np.asarray(unfused["plan"]["predicted_contacts"]).reshape(-1, 3)
        touched = ", ".join(unfused.get("pads_in_contact", [])) or "nothing"
        what = f"touched {touched}" if unfused["executed"] else "not executed"
        label = (
            f"{unfused['chosen_by']['strategy']} ({unfused['gripper']}), {what}: not fused "
            "(planned contacts)"
        )
        marks.append(GraspMarks(label, planned, np.full(len(planned), "planned"), fused=False))
    grasps_figure(
        out_path,
        result.selected.completed,
        truth.vertices,
        marks,
        title=f"{name}: grasps from above, median deviation after each",
    )


def run_trial(
    config: Config,
    registry: StageRegistry,
    out_dir: Path,
    report: Callable[[str], None] = lambda message: None,
) -> TrialRecord:
    """Run one simulated trial as ``config`` says and write everything to ``out_dir``.

    Args:
        out_dir: an empty folder to write into (the caller's output-folder policy,
            :mod:`pipeline.outdir`, chose it).
        report: called with a short message as each phase starts (progress output).

    Raises:
        StageFailure: a stage could not produce a result (empty segmentation, refused grasp,
            rejected initialisation); ``result.json`` records how far the trial got.
        PluginRaised: a plugin raised; once the trial has written data, ``result.json``
            records the failure too.
        SymfuseError: bad config or object (before anything but ``config.toml`` is written).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    config.write(out_dir / "config.toml")
    settings = config.trial
    timer = PhaseTimer()
    document: dict[str, Any] = {
        "symfuse": __version__,
        "command": "trial",
        "object": settings.object,
        "gripper": settings.gripper,
        "seed": settings.seed,
        "stages_used": dict(config.choices),
        "status": "running",
        "config": config.to_dict(),
    }
    stages = {stage: config.create(registry, stage) for stage in config.choices}
    obj = load_object(settings.object, units=settings.units, symmetry=settings.symmetry)
    try:
        return _simulate(config, registry, stages, obj, out_dir, timer, document, report)
    except SymfuseError as exc:
        # A failure after the first data file is a result: record how far the trial got.
        if any(path.name != "config.toml" for path in out_dir.iterdir()):
            document.update(status="failed", reason=str(exc), timings=timer.seconds)
            write_json(out_dir / "result.json", document)
        raise


def _simulate(
    config: Config,
    registry: StageRegistry,
    stages: dict[str, Any],
    obj: CatalogueObject,
    out_dir: Path,
    timer: PhaseTimer,
    document: dict[str, Any],
    report: Callable[[str], None],
) -> TrialRecord:
    """The body of :func:`run_trial`: simulate, estimate, evaluate, write. A first grasp
    that misses (:class:`MissedGrasp`) is released and the object looked at and grasped
    again, unlike every grasp that missed, up to ``trial.retries`` times."""
    settings = config.trial
    world = stages["world"]
    report(f"scene: {settings.object} with {settings.gripper}")
    try:
        with timer.phase("scene"):
            world.load_scene(
                SceneSetup(
                    obj,
                    x_m=settings.x_m,
                    y_m=settings.y_m,
                    yaw_rad=float(np.radians(settings.yaw_deg)),
                    seed=settings.seed,
                )
            )
        missed: list[MissedGrasp] = []
        document["missed_grasps"] = []
        while True:
            pose_before, observation, cloud, proposal, choice = _look_and_plan(
                config, registry, stages, out_dir, timer, document, report, missed
            )
            try:
                fused = _grasp_and_fuse(
                    config,
                    registry,
                    stages,
                    obj,
                    world,
                    observation,
                    pose_before,
                    cloud,
                    proposal,
                    choice,
                    out_dir,
                    timer,
                    document,
                    report,
                )
                break
            except MissedGrasp as miss:
                if len(missed) >= settings.retries:
                    raise MissedGrasp(
                        f"{miss}{next_try(world.hands, miss.plan.gripper)}", miss.plan
                    ) from None
                # Release, look again (the pads pushed the object) and grasp unlike this.
                document["missed_grasps"].append(document.pop("unfused_grasp"))
                missed.append(miss)
                report(f"{miss}; grasping again ({len(missed)} of {settings.retries})")
                with timer.phase("grasp"):
                    world.release()
    finally:
        world.close()

    result, truth, evaluated = fused.result, fused.truth, fused.evaluated
    metrics = [stage_metrics for stage_metrics, _ in evaluated]
    with timer.phase("write"):
        write_completed_clouds(out_dir, result)
        truth_mesh = obj.mesh.copy().apply_transform(fused.object_after.transform)
        truth_mesh.export(out_dir / "object_final.ply")
    with timer.phase("model"):
        model, document["model"] = write_model(
            out_dir, result, config.model, observation.table_height_m, cloud.viewpoint_m
        )
    if model is not None:
        with timer.phase("evaluation"):
            scores = model_scores(model, truth)
        metrics = [{**m, **scores[s.stage]} for m, s in zip(metrics, result.stages, strict=True)]
    if settings.pictures:
        with timer.phase("pictures"):
            draw_pictures(out_dir, config, cloud.points, fused.init, result, evaluated, truth)
            draw_grasps(out_dir / "grasps.png", settings.object, result, truth, fused, document)
    document.update(
        status=result.final.status,
        stages=[
            {**stage_json, "metrics": stage_metrics}
            for stage_json, stage_metrics in zip(estimate_to_json(result), metrics, strict=True)
        ],
        **selection_to_json(result),
        timings=timer.seconds,
    )
    write_json(out_dir / "result.json", document)
    return TrialRecord(out_dir, result, metrics, dict(timer.seconds), document)


class MissedGrasp(StageFailure):
    """The first grasp's pads did not touch opposing sides (:func:`unfused_reason`): there
    is nothing to fuse. ``plan`` is the grasp that missed; the trial looks again and grasps
    unlike it while ``trial.retries`` allows."""

    def __init__(self, message: str, plan: GraspPlan) -> None:
        super().__init__(message)
        self.plan = plan


def _look_and_plan(
    config: Config,
    registry: StageRegistry,
    stages: dict[str, Any],
    out_dir: Path,
    timer: PhaseTimer,
    document: dict[str, Any],
    report: Callable[[str], None],
    missed: list[MissedGrasp],
) -> tuple[ObjectPose, DepthObservation, PointCloud, SymmetryInit, HandChoice]:
    """Sense, segment, propose a plane and choose the hand and grasp, unlike the grasps
    that ``missed`` (:func:`~pipeline.hand_choice.choose_grasp`); the hand is in the scene
    when it returns. Writes the view's files and ``document``'s entries for them (a later
    look replaces an earlier one's). Returns the object's pose when seen, the observation,
    the cloud, the proposal and the choice.

    Raises:
        StageFailure: segmentation found no object, or no hand can grasp it (after a miss:
            no grasp unlike those that missed; the miss is then the trial's failure).
    """
    from .images import save_depth, save_rgb

    settings = config.trial
    world = stages["world"]
    pose_before = world.object_pose()
    report("sensing")
    with timer.phase("sensor"):
        observation = stages["sensor"].observe(world)
    if settings.pictures:
        with timer.phase("pictures"):
            save_rgb(out_dir / "rgb.png", observation.rgb)
            save_depth(out_dir / "depth.png", observation.depth_m)
    with timer.phase("write"):
        np.save(out_dir / "depth.npy", observation.depth_m)
        write_json(out_dir / "camera.json", camera_to_json(observation))
    report("segmenting")
    with timer.phase("segmenter"):
        cloud = stages["segmenter"].segment(observation)
    with timer.phase("write"):
        write_cloud(out_dir / "cloud.ply", cloud.points)
    document["object_pose_before"] = pose_to_json(pose_before)
    document["points"] = len(cloud)
    report("initialising and planning")
    with timer.phase("initialiser"):
        proposal = stages["initialiser"].propose(cloud, observation)
    with timer.phase("planner"):
        # Without a tool change the hand that missed makes every later attempt.
        hands = world.hands if world.gripper is None or world.changes_hands else ()
        grippers = {name: world.gripper_spec(name) for name in hands or (world.gripper.name,)}
        choice = choose_grasp(
            config,
            registry,
            cloud,
            proposal,
            grippers,
            observation.table_height_m,
            [miss.plan for miss in missed],
        )
    plan = choice.plan
    if plan.status != "ok" and missed:
        raise MissedGrasp(f"{missed[-1]}; no grasp unlike it: {plan.reason}", missed[-1].plan)
    document["gripper"] = choice.answer.gripper
    document["hand"] = choice_to_json(choice)
    if choice.answer.planner:
        document["stages_used"]["planner"] = choice.answer.planner
    document["plan"] = plan_to_json(plan)
    if plan.status != "ok":
        if not choice.answer.planner:
            raise StageFailure(plan.reason)
        raise StageFailure(f"grasp planner '{choice.answer.planner}' refused: {plan.reason}")
    with timer.phase("grasp"):
        if world.gripper is not None and world.gripper.name != plan.gripper:
            world.remove_hand()
        if world.gripper is None:
            world.add_hand(plan.gripper)
    return pose_before, observation, cloud, proposal, choice


@dataclass(frozen=True)
class Fused:
    """What the grasps of a trial left: the estimate after the last grasp fused, the truth
    it is scored against (the object after that grasp), each stage's evaluation, the
    initial state and every grasp's contacts."""

    init: SymmetryInit
    result: EstimateResult
    truth: GroundTruth
    evaluated: list[tuple[dict[str, Any], np.ndarray]]
    object_after: ObjectPose
    contacts: tuple[Contacts, ...]


def _grasp_and_fuse(
    config: Config,
    registry: StageRegistry,
    stages: dict[str, Any],
    obj: CatalogueObject,
    world: World,
    observation: DepthObservation,
    pose_seen: ObjectPose,
    cloud: PointCloud,
    proposal: SymmetryInit,
    choice: HandChoice,
    out_dir: Path,
    timer: PhaseTimer,
    document: dict[str, Any],
    report: Callable[[str], None],
) -> Fused:
    """Grasp, read the taxels and fuse every grasp so far, up to ``trial.grasps`` times:
    the hand releases the object and withdraws (:meth:`World.release`) before each new
    grasp, which is planned on the current
    model (:mod:`pipeline.next_grasp`). The stop rule ends it earlier, and so does a later
    grasp the planner cannot find, the hand cannot execute or that touches nothing or one
    side only (it is not fused). ``contacts.json`` and ``document["grasps"]`` grow by one
    grasp each time.

    Raises:
        StageFailure: the first grasp was not executed, touched nothing or one side only,
            or the initialiser rejected it.
    """
    settings = config.trial
    until_m = 1e-3 * settings.until_std_mm if settings.until_std_mm > 0 else None
    hands = next_hands(config, registry, world, choice)
    model = measurement_model(config, registry)
    # The next-grasp draws have their own stream: the world's noise does not depend on them.
    rng = np.random.default_rng([settings.seed, 15])
    grasps: list[Contacts] = []
    plans: list[GraspPlan] = []
    document["grasps"] = []
    document["next_grasp"] = settings.next_grasp if settings.grasps > 1 else None
    plan, chosen_by, fused, stop = choice.plan, {"strategy": "first"}, None, ""
    for k in range(settings.grasps):
        if k > 0:
            report(f"planning grasp {k + 1} ({settings.next_grasp})")
            with timer.phase("planner"):
                following = choose_next_grasp(
                    settings.next_grasp,
                    tuple(hands.values()),
                    fused.result.selected,
                    model,
                    rng,
                    cloud.viewpoint_m,
                    tuple(plans),
                )
            plan, chosen_by = following.plan, following.to_json()
            if plan.status != "ok":
                stop = f"no feasible grasp {k + 1}: {plan.reason}"
                break
        report(f"grasp {k + 1} with {plan.gripper}")
        with timer.phase("grasp"):
            if k > 0:
                released = world.release()
                if plan.gripper != world.gripper.name:
                    world.remove_hand()
                    world.add_hand(plan.gripper)
            outcome = world.execute_grasp(plan)
        shift_m, tilt_rad = object_motion(obj.mesh, outcome.object_before, outcome.object_after)
        executed = {
            **({"object_pose_released": pose_to_json(released)} if k > 0 else {}),
            "object_pose_grasped": pose_to_json(outcome.object_after),
            "executed": outcome.executed,
            "aperture_m": outcome.aperture_m,
            "joint_positions": outcome.joint_positions,
            "T_robot_hand": np.asarray(outcome.T_robot_hand).tolist(),
            "reason": outcome.reason,
            "reapproaches": outcome.reapproaches,
            "object_shift_mm": 1e3 * shift_m,
            "object_tilt_deg": float(np.degrees(tilt_rad)),
            "object_turn_deg": float(
                np.degrees(object_turn(outcome.object_before, outcome.object_after))
            ),
        }
        if k == 0:
            document["grasp"] = executed
            document["object_pose_after"] = pose_to_json(outcome.object_after)
            if not outcome.executed:
                raise StageFailure(
                    f"grasp not executed: {outcome.reason}{next_try(world.hands, plan.gripper)}"
                )
        elif not outcome.executed:
            stop = f"grasp {k + 1} not executed: {outcome.reason}"
            document["unfused_grasp"] = attempt_to_json(k, plan, chosen_by, executed)
            break
        with timer.phase("tactile"):
            contacts = stages["tactile"].read(world, outcome)
        stop = unfused_reason(k, contacts, shift_m, tilt_rad)
        if stop:
            document["unfused_grasp"] = attempt_to_json(k, plan, chosen_by, executed, contacts)
            if k == 0:
                if len(contacts):  # the taxels are kept for `symfuse fuse`, as read
                    with timer.phase("write"):
                        write_json(out_dir / "contacts.json", contacts_to_json([contacts], [plan]))
                raise MissedGrasp(stop, plan)
            break
        grasps.append(contacts)
        plans.append(plan)
        with timer.phase("write"):
            write_json(out_dir / "contacts.json", contacts_to_json(grasps, plans))
        if k == 0:
            init = _initial_state(config, stages, proposal, cloud, plan, contacts, timer, document)
        report(f"fusing {len(grasps)} grasp(s)")
        with timer.phase("estimator"):
            result = estimate(config, registry, cloud, init, grasps, observation)
        with timer.phase("evaluation"):
            truth = ground_truth(
                obj, outcome.object_after, pose_seen, observation.calibration_error
            )
            centre = np.asarray(plan.T_robot_hand)[:2, 3]
            evaluated = [evaluate_stage(stage, truth, centre) for stage in result.stages]
        known = uncertainty(result.selected)
        fused = Fused(init, result, truth, evaluated, outcome.object_after, tuple(grasps))
        document["grasps"].append(
            grasp_to_json(
                k,
                plan,
                hands[plan.gripper].planner.name,
                chosen_by,
                executed,
                contacts,
                fused,
                known,
            )
        )
        document["object_pose_after"] = pose_to_json(outcome.object_after)
        stop = stop_reason(known, k + 1, settings.grasps, until_m)
        if stop:
            break
    document["taxels_in_contact"] = sum(len(c) for c in grasps)
    document["stop_reason"] = stop
    return fused


def next_hands(
    config: Config, registry: StageRegistry, world: World, choice: HandChoice
) -> dict[str, NextHand]:
    """The hands later grasps may be made with, by name, each with one planner.

    With ``trial.gripper = "auto"`` in a world that changes hands
    (:attr:`~pipeline.stages.World.changes_hands`), every hand a planner answered for when
    the first grasp's hand was chosen: the next-grasp strategy then chooses the hand too
    (a tool change, docs/method.md §11). Otherwise the first grasp's hand alone. The first
    grasp's hand keeps its planner; another hand takes the first planner that answered
    for it.
    """
    answers = (choice.answer, *choice.answers) if world.changes_hands else (choice.answer,)
    hands: dict[str, NextHand] = {}
    for answer in answers:
        if answer.gripper not in hands:
            planner = create_planner(config, registry, answer.planner)
            hands[answer.gripper] = NextHand(planner, world.gripper_spec(answer.gripper))
    return hands


def attempt_to_json(
    k: int,
    plan: GraspPlan,
    chosen_by: dict[str, Any],
    executed: dict[str, Any],
    contacts: Contacts | None = None,
) -> dict[str, Any]:
    """A grasp as planned, chosen and executed (and what it touched, when read): the part
    of a ``grasps`` entry before the estimate, and ``result.json``'s ``unfused_grasp``, the
    grasp a trial stopped on (not executed, or touching too little to fuse)."""
    touched = {}
    if contacts is not None:
        touched = {
            "taxels_in_contact": len(contacts),
            "pads_in_contact": sorted(set(contacts.pads.tolist())),
        }
    return {
        "grasp": k + 1,
        "gripper": plan.gripper,
        "chosen_by": chosen_by,
        "plan": plan_to_json(plan),
        **executed,
        **touched,
    }


def unfused_reason(k: int, contacts: Contacts, shift_m: float, tilt_rad: float) -> str:
    """Why grasp ``k`` (from 0) is not fused, or ``""``: a grasp that touched nothing or one
    side only (no two pads pressing from opposing sides,
    :func:`~pipeline.evaluation.opposing_contacts`). Nothing held the object against the
    pads that touched: they pushed it by an amount no taxel measures, and taxels on one
    side cannot tell that push from the object's width, so the contacts cannot locate it.
    A later grasp's estimate stays the last one, scored against the object as it was then;
    a first grasp leaves no estimate to fuse into (docs/method.md §10). ``shift_m`` and
    ``tilt_rad``: how the grasp moved the object."""
    if opposing_contacts(contacts):
        return ""
    touched = "nothing" if len(contacts) == 0 else "one side only"
    return (
        f"grasp {k + 1} touched {touched} (the object moved {1e3 * shift_m:.1f} mm "
        f"and tilted {np.degrees(tilt_rad):.1f} deg); not fused"
    )


def _initial_state(
    config: Config,
    stages: dict[str, Any],
    proposal: SymmetryInit,
    cloud: PointCloud,
    plan: GraspPlan,
    contacts: Contacts,
    timer: PhaseTimer,
    document: dict[str, Any],
) -> SymmetryInit:
    """Stage 0 from the proposal and the first grasp (``document["init"]``).

    Raises:
        StageFailure: the initialiser rejected every hypothesis.
    """
    with timer.phase("initialiser"):
        init = stages["initialiser"].refine(proposal, cloud, plan, contacts)
    document["init"] = {
        "plane": plane_to_json(init.plane),
        "symmetry": symmetry_to_json(init.proposed),
        "kind_scores": init.kind_scores,
        "bias": bias_to_json(init.bias),
        "status": init.status,
        "hypotheses": [
            {**plane_to_json(h.plane), "score": h.score, "violations": h.violations}
            for h in init.hypotheses[:20]
        ],
    }
    if init.status != "ok":
        raise StageFailure(f"initialiser '{config.choices['initialiser']}' rejected: {init.reason}")
    return init


def measurement_model(config: Config, registry: StageRegistry) -> MeasurementModel:
    """The taxel model the information score predicts with: the ``iekf`` estimator's
    parameters (whichever estimator fuses, the score is the IEKF's)."""
    params = config.params["estimator"].get("iekf")
    if params is None:
        params = registry.get("estimator", "iekf").cls.Params()
    return MeasurementModel(
        window_std_m=(params.window_along_normal_m, params.window_across_normal_m),
        noise_std_m=(params.noise_along_normal_m, params.noise_across_normal_m),
        point_std_m=params.point_std_m,
        facing_filter=params.facing_filter,
        regrasp_noise=regrasp_noise(params),
    )


def grasp_to_json(
    k: int,
    plan: GraspPlan,
    planner: str,
    chosen_by: dict[str, Any],
    executed: dict[str, Any],
    contacts: Contacts,
    fused: Fused,
    known: Uncertainty,
) -> dict[str, Any]:
    """One entry of ``result.json``'s ``grasps``: how the grasp was chosen and went, and
    the estimate after fusing it and every grasp before (each stage without its iteration
    trace, with its metrics against the object after this grasp)."""
    stages = [
        {key: value for key, value in stage_json.items() if key != "trace"}
        | {"metrics": stage_metrics}
        for stage_json, (stage_metrics, _) in zip(
            estimate_to_json(fused.result), fused.evaluated, strict=True
        )
    ]
    return {
        **attempt_to_json(k, plan, chosen_by, executed, contacts),
        "planner": planner,
        "status": fused.result.final.status,
        **selection_to_json(fused.result),
        "uncertainty": known.to_json(),
        "stages": stages,
    }
