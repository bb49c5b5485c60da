"""One full simulated grasp trial, from the camera to the evaluated estimate.

    world -> sensor -> segmenter -> initialiser.propose -> planner (and hand choice)
      -> grasp -> tactile -> initialiser.refine -> estimator -> evaluation

The configured world (a stage like the others, :class:`pipeline.stages.World`) builds the
scene; it is sensed before its hand is chosen (:mod:`pipeline.planning.hand_choice`) among the hands
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
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.catalogue.objects import CatalogueObject
from pipeline.catalogue.rest import scene_object
from pipeline.config import Config, TrialSettings
from pipeline.errors import StageFailure, SymfuseError
from pipeline.io.after_view_files import write_after_view
from pipeline.io.camera_file import camera_to_json
from pipeline.io.formats import (
    contacts_to_json,
    plan_to_json,
    selection_to_json,
    write_cloud,
    write_json,
)
from pipeline.metrics import DeviationSummary
from pipeline.metrics.evaluation import (
    GroundTruth,
    deviation_floor,
    evaluate_stage,
    model_scores,
    object_motion,
    object_turn,
    opposing_contacts,
)
from pipeline.params import to_toml
from pipeline.perception.after_view import look_after
from pipeline.planning.hand_choice import HandChoice, Planners, choose_grasp, next_try
from pipeline.planning.next_grasp import (
    MeasurementModel,
    NextHand,
    Uncertainty,
    choose_next_grasp,
    stop_reason,
    uncertainty,
)
from pipeline.registry import StageRegistry
from pipeline.run.result_document import estimate_entries, write_estimate_files
from pipeline.run.runner import estimate_with, one_blas_thread
from pipeline.run.trial_document import TrialDocument, pose_to_json
from pipeline.stages import (
    STAGES,
    Estimator,
    Segmenter,
    SensorSource,
    SymmetryInitialiser,
    TactileModel,
    World,
)
from pipeline.symmetry.scoring import true_kind
from pipeline.symmetry.truth_file import true_symmetries
from pipeline.types import (
    AfterView,
    Contacts,
    DepthObservation,
    EstimateResult,
    GraspOutcome,
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
    """Wall time per named phase, in seconds, in the order the phases ran, and the
    process's processor time (user + system) in each (what a phase costs on a loaded
    machine, where its wall time mostly says how long it waited)."""

    seconds: dict[str, float] = field(default_factory=dict)
    cpu_seconds: dict[str, float] = field(default_factory=dict)

    @contextmanager
    def phase(self, name: str) -> Iterator[None]:
        started, started_cpu = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - started
            cpu = time.process_time() - started_cpu
            self.cpu_seconds[name] = self.cpu_seconds.get(name, 0.0) + cpu


@dataclass(frozen=True)
class TrialRecord:
    """What :func:`run_trial` returns: the estimate, its evaluation, the output folder and
    the phases' wall and processor times (s, :class:`PhaseTimer`)."""

    out_dir: Path
    result: EstimateResult
    metrics: list[dict[str, Any]]
    timings: dict[str, float]
    document: dict[str, Any]
    cpu_timings: dict[str, float] = field(default_factory=dict)


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
    # A box's thickness and a cylinder's diameter are measured across the upright object.
    upright = obj.rest is None or obj.rest.keeps_vertical
    return GroundTruth(
        vertices=vertices,
        faces=np.asarray(obj.mesh.faces),
        symmetry=obj.symmetry,
        plane=plane,
        # The object origin, or the true plane's point nearest it (a mesh's plane given
        # by the user need not pass through the centre of its bounding box).
        axis_xy_m=anchor[:2].copy(),
        thickness_m=dims.get("thickness") if obj.kind == "box" and upright else None,
        diameter_m=dims.get("diameter") if obj.kind == "cylinder" and upright else None,
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
    from pipeline.reports.trial_pictures import (
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
    the trial released without fusing it, where it was planned to touch."""
    from pipeline.reports.trial_pictures import GraspMarks, grasps_picture

    marks = []
    for contacts, entry in zip(fused.contacts, document["grasps"], strict=True):
        stage = entry["selected_stage"]
        median_mm = 1e3 * entry["stages"][stage]["metrics"]["deviation_m"]["median"]
        chosen = f"{entry['chosen_by']['strategy']} ({entry['gripper']})"
        label = f"{chosen}, then {median_mm:.1f} mm (Stage {stage})"
        marks.append(GraspMarks(label, contacts.positions, contacts.pads))
    for unfused in document.get("unfused_grasps", []):
        planned = np.asarray(unfused["plan"]["predicted_contacts"]).reshape(-1, 3)
        touched = ", ".join(unfused.get("pads_in_contact", [])) or "nothing"
        what = f"touched {touched}" if unfused["executed"] else "not executed"
        label = (
            f"{unfused['chosen_by']['strategy']} ({unfused['gripper']}), {what}: not fused "
            "(planned contacts)"
        )
        marks.append(GraspMarks(label, planned, np.full(len(planned), "planned"), fused=False))
    grasps_picture(
        out_path,
        result.selected.completed,
        truth.vertices,
        marks,
        title=f"{name}: grasps from above, median deviation after each",
    )


@dataclass(frozen=True)
class TrialStages:
    """The stages of one trial, each built once from the config: the world, the sensor,
    the segmenter, the initialiser, the tactile model and the estimator, and the planners
    (built by name as hand choice asks for them,
    :class:`~pipeline.planning.hand_choice.Planners`)."""

    world: World
    sensor: SensorSource
    segmenter: Segmenter
    initialiser: SymmetryInitialiser
    planners: Planners
    tactile: TactileModel
    estimator: Estimator

    @classmethod
    def build(cls, config: Config, registry: StageRegistry) -> TrialStages:
        """Every configured stage, in pipeline order (a stage's own checks of its
        parameters run as it is built, so a bad one fails before the scene is loaded)."""
        planners = Planners(config, registry)
        built = {
            stage: planners(config.choices[stage])
            if stage == "planner"
            else config.create(registry, stage)
            for stage in STAGES
        }
        built["planners"] = planners
        del built["planner"]
        return cls(**built)


@dataclass(frozen=True)
class Trial:
    """One running trial: its config, its stages, the object, the output folder, the
    phase timer, the result document it fills in (``record``, written as ``result.json``)
    and the progress callback."""

    config: Config
    registry: StageRegistry
    stages: TrialStages
    obj: CatalogueObject
    out_dir: Path
    timer: PhaseTimer
    record: TrialDocument
    report: Callable[[str], None]

    @property
    def settings(self) -> TrialSettings:
        return self.config.trial

    @property
    def world(self) -> World:
        return self.stages.world

    def phase(self, name: str) -> AbstractContextManager[None]:
        """Time the block as the phase ``name`` (:class:`PhaseTimer`)."""
        return self.timer.phase(name)


@dataclass(frozen=True)
class Look:
    """What one look at the scene left (:func:`_look_and_plan`): the object's pose when
    seen, the observation, the object's cloud, the initialiser's proposal and the chosen
    hand and grasp."""

    pose_seen: ObjectPose
    observation: DepthObservation
    cloud: PointCloud
    proposal: SymmetryInit
    choice: HandChoice


def run_trial(
    config: Config,
    registry: StageRegistry,
    out_dir: Path,
    report: Callable[[str], None] = lambda message: None,
) -> TrialRecord:
    """Run one simulated trial as ``config`` says and write everything to ``out_dir``.

    Args:
        out_dir: an empty folder to write into (the caller's output-folder policy,
            :mod:`pipeline.io.outdir`, chose it).
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
    record = TrialDocument(config)
    stages = TrialStages.build(config, registry)
    obj = scene_object(settings)
    record.placed(obj.rest, true_kind(true_symmetries(obj)))
    trial = Trial(config, registry, stages, obj, out_dir, PhaseTimer(), record, report)
    try:
        with one_blas_thread():  # small matrices: BLAS threads only contend
            return _simulate(trial)
    except SymfuseError as exc:
        # A failure after the first data file is a result: record how far the trial got.
        if any(path.name != "config.toml" for path in out_dir.iterdir()):
            record.fail(out_dir, str(exc), trial.timer.seconds)
        raise


def _simulate(trial: Trial) -> TrialRecord:
    """The body of :func:`run_trial`: simulate, estimate, evaluate, write."""
    settings, world = trial.settings, trial.world
    trial.report(f"scene: {settings.object} with {settings.gripper}")
    try:
        with trial.phase("scene"):
            world.load_scene(
                SceneSetup(
                    trial.obj,
                    x_m=settings.x_m,
                    y_m=settings.y_m,
                    yaw_rad=float(np.radians(settings.yaw_deg)),
                    seed=settings.seed,
                )
            )
        look, fused = _grasp_until_held(trial)
    finally:
        world.close()
    return _write_results(trial, look, fused)


def _grasp_until_held(trial: Trial) -> tuple[Look, Fused]:
    """Look, plan and grasp; a first grasp that misses (:class:`MissedGrasp`) is released
    and the object looked at and grasped again, unlike every grasp that missed, up to
    ``trial.retries`` times. The last look and what its grasps fused."""
    settings, world, record = trial.settings, trial.world, trial.record
    missed: list[MissedGrasp] = []
    record.start_looking()
    while True:
        look = _look_and_plan(trial, missed)
        try:
            return look, _grasp_and_fuse(trial, look)
        except MissedGrasp as miss:
            if len(missed) >= settings.retries:
                raise MissedGrasp(
                    f"{miss}{next_try(world.hands, miss.plan.gripper)}", miss.plan
                ) from None
            # Release, look again (the pads pushed the object) and grasp unlike this.
            record.missed()
            missed.append(miss)
            trial.report(f"{miss}; grasping again ({len(missed)} of {settings.retries})")
            with trial.phase("grasp"):
                world.release()


def _write_results(trial: Trial, look: Look, fused: Fused) -> TrialRecord:
    """The estimate's files, the model and its scores, the pictures and ``result.json``."""
    out_dir, record = trial.out_dir, trial.record
    result, truth, evaluated = fused.result, fused.truth, fused.evaluated
    metrics = [stage_metrics for stage_metrics, _ in evaluated]
    with trial.phase("write"):
        truth_mesh = trial.obj.mesh.copy().apply_transform(fused.object_after.transform)
        truth_mesh.export(out_dir / "object_final.ply")
    with trial.phase("model"):
        model, entry = write_estimate_files(
            out_dir,
            result,
            trial.config.model,
            look.observation.table_height_m,
            look.cloud.viewpoint_m,
        )
        record.model(entry)
    if model is not None:
        with trial.phase("evaluation"):
            scores = model_scores(model, truth)
        metrics = [{**m, **scores[s.stage]} for m, s in zip(metrics, result.stages, strict=True)]
    if trial.settings.pictures:
        with trial.phase("pictures"):
            draw_pictures(
                out_dir, trial.config, look.cloud.points, fused.init, result, evaluated, truth
            )
            draw_grasps(
                out_dir / "grasps.png", trial.settings.object, result, truth, fused, record.data
            )
    record.finish(out_dir, result, metrics, trial.timer.seconds)
    timer = trial.timer
    return TrialRecord(
        out_dir, result, metrics, dict(timer.seconds), record.data, dict(timer.cpu_seconds)
    )


class MissedGrasp(StageFailure):
    """The first grasp's pads did not touch opposing sides (:func:`unfused_reason`), or the
    hand could not execute it: there is nothing to fuse. ``plan`` is the grasp that missed;
    the trial looks again and grasps unlike it while ``trial.retries`` allows."""

    def __init__(self, message: str, plan: GraspPlan) -> None:
        super().__init__(message)
        self.plan = plan


def _look_and_plan(trial: Trial, missed: list[MissedGrasp]) -> Look:
    """Sense, segment, propose a plane and choose the hand and grasp, unlike the grasps
    that ``missed`` (:func:`~pipeline.planning.hand_choice.choose_grasp`); the hand is in the scene
    when it returns. Writes the view's files and the record's entries for them (a later
    look replaces an earlier one's).

    Raises:
        StageFailure: segmentation found no object, or no hand can grasp it (after a miss:
            no grasp unlike those that missed; the miss is then the trial's failure).
    """
    from pipeline.io.images import save_depth, save_rgb

    stages, world, out_dir = trial.stages, trial.world, trial.out_dir
    pose_seen = world.object_pose()
    trial.report("sensing")
    with trial.phase("sensor"):
        observation = stages.sensor.observe(world)
    if trial.settings.pictures:
        with trial.phase("pictures"):
            save_rgb(out_dir / "rgb.png", observation.rgb)
            save_depth(out_dir / "depth.png", observation.depth_m)
    with trial.phase("write"):
        np.save(out_dir / "depth.npy", observation.depth_m)
        write_json(out_dir / "camera.json", camera_to_json(observation))
    trial.report("segmenting")
    with trial.phase("segmenter"):
        cloud = stages.segmenter.segment(observation)
    with trial.phase("write"):
        write_cloud(out_dir / "cloud.ply", cloud.points)
    trial.record.view(pose_seen, len(cloud))
    trial.report("initialising and planning")
    with trial.phase("initialiser"):
        proposal = stages.initialiser.propose(cloud, observation)
    with trial.phase("planner"):
        # Without a tool change the hand that missed makes every later attempt.
        hands = world.hands if world.gripper is None or world.changes_hands else ()
        grippers = {name: world.gripper_spec(name) for name in hands or (world.gripper.name,)}
        choice = choose_grasp(
            trial.config,
            trial.registry,
            cloud,
            proposal,
            grippers,
            observation.table_height_m,
            [miss.plan for miss in missed],
            stages.planners,
        )
    _take_choice(trial, choice, missed)
    return Look(pose_seen, observation, cloud, proposal, choice)


def _take_choice(trial: Trial, choice: HandChoice, missed: list[MissedGrasp]) -> None:
    """Record the hand and grasp chosen and bring the hand into the scene.

    Raises:
        StageFailure: no hand can grasp the object (after a miss: no grasp unlike those that
            missed; the miss is then the trial's failure).
    """
    plan, world = choice.plan, trial.world
    if plan.status != "ok" and missed:
        raise MissedGrasp(f"{missed[-1]}; no grasp unlike it: {plan.reason}", missed[-1].plan)
    trial.record.choice(choice)
    if plan.status != "ok":
        if not choice.answer.planner:
            raise StageFailure(plan.reason)
        # A hand no planner was asked for (a named --gripper) is the next thing to try.
        asked = {answer.gripper for answer in choice.answers}
        untried = tuple(hand for hand in world.hands if hand not in asked)
        raise StageFailure(
            f"grasp planner '{choice.answer.planner}' refused: {plan.reason}"
            f"{next_try(untried, plan.gripper)}"
        )
    with trial.phase("grasp"):
        if world.gripper is not None and world.gripper.name != plan.gripper:
            world.remove_hand()
        if world.gripper is None:
            world.add_hand(plan.gripper)


@dataclass(frozen=True)
class Fused:
    """What the grasps of a trial left: the estimate after the last grasp fused, the truth
    it is scored against (the object after that grasp), each stage's evaluation, the
    initial state, every grasp's contacts and the selected stage's deviation floor
    (:func:`~pipeline.metrics.evaluation.deviation_floor`: its points with the true bias
    and plane; None where the truth cannot give it)."""

    init: SymmetryInit
    result: EstimateResult
    truth: GroundTruth
    evaluated: list[tuple[dict[str, Any], np.ndarray]]
    object_after: ObjectPose
    contacts: tuple[Contacts, ...]
    floor: DeviationSummary | None = None


@dataclass(frozen=True)
class Attempt:
    """One grasp as planned, chosen and executed (:func:`_execute`): its number ``k``
    (from 0), the plan, how it was chosen, the world's outcome, its ``executed`` entry of
    the record, and how far it moved (m) and tilted (rad) the object."""

    k: int
    plan: GraspPlan
    chosen_by: dict[str, Any]
    outcome: GraspOutcome
    executed: dict[str, Any]
    shift_m: float
    tilt_rad: float

    def to_json(self, contacts: Contacts | None = None) -> dict[str, Any]:
        """:func:`attempt_to_json` of this grasp (and what it touched, when read)."""
        return attempt_to_json(self.k, self.plan, self.chosen_by, self.executed, contacts)


def _grasp_and_fuse(trial: Trial, look: Look) -> Fused:
    """Grasp, read the taxels and fuse every grasp so far, up to ``trial.grasps`` times:
    the hand releases the object and withdraws (:meth:`World.release`) before each new
    grasp, which is planned on the current model (:mod:`pipeline.planning.next_grasp`). The stop
    rule ends it earlier, and so does a later grasp the planner cannot find, the hand
    cannot execute or that touches nothing or one side only (it is not fused).
    ``contacts.json`` and the record's ``grasps`` grow by one grasp each time.

    Raises:
        MissedGrasp: the first grasp was not executed, or touched nothing or one side only.
        StageFailure: the initialiser rejected it.
    """
    settings, record = trial.settings, trial.record
    until_m = 1e-3 * settings.until_std_mm if settings.until_std_mm > 0 else None
    hands = next_hands(trial.world, trial.stages.planners, look.choice)
    model = measurement_model(trial)
    # The next-grasp draws have their own stream: the world's noise does not depend on them.
    rng = np.random.default_rng([settings.seed, 15])
    grasps: list[Contacts] = []
    plans: list[GraspPlan] = []
    views: list[AfterView | None] = []
    entries: list[dict[str, Any]] = []
    record.start_grasping(settings.next_grasp if settings.grasps > 1 else None)
    unfused: list[GraspPlan] = []
    plan, chosen_by, fused, stop = look.choice.plan, {"strategy": "first"}, None, ""
    for k in range(settings.grasps):
        if k > 0:
            trial.report(f"planning grasp {k + 1} ({settings.next_grasp})")
            with trial.phase("planner"):
                following = choose_next_grasp(
                    settings.next_grasp,
                    tuple(hands.values()),
                    fused.result.selected,
                    model,
                    rng,
                    look.cloud.viewpoint_m,
                    tuple(plans),
                    tuple(unfused),
                )
            plan, chosen_by = following.plan, following.to_json()
            if plan.status != "ok":
                stop = f"no feasible grasp {k + 1}: {plan.reason}"
                break
        attempt = _execute(trial, k, plan, chosen_by)
        contacts, why = _read_taxels(trial, attempt)
        if why:
            # A later grasp that held nothing leaves the estimate as it was; the hand
            # releases the object before the next, planned unlike this one.
            unfused.append(plan)
            known = uncertainty(fused.result.selected)
            stop = stop_reason(known, k + 1, settings.grasps, until_m, len(unfused))
            if stop:
                break
            trial.report(f"{why}; released, planning another")
            continue
        grasps.append(contacts)
        plans.append(plan)
        views.append(_look_after(trial, look, attempt))
        with trial.phase("write"):
            entries.append(write_after_view(trial.out_dir, k, views[-1], attempt.outcome))
            write_json(trial.out_dir / "contacts.json", contacts_to_json(grasps, plans, entries))
        init = fused.init if fused else _initial_state(trial, look, plan, contacts)
        fused = _fuse(trial, look, attempt, init, tuple(grasps), tuple(views))
        known = uncertainty(fused.result.selected)
        planner = hands[plan.gripper].planner.name
        record.fused(grasp_to_json(attempt, planner, contacts, fused, known), fused.object_after)
        stop = stop_reason(known, k + 1, settings.grasps, until_m, len(unfused))
        if stop:
            break
    record.stopped(sum(len(c) for c in grasps), stop)
    return fused


def _execute(trial: Trial, k: int, plan: GraspPlan, chosen_by: dict[str, Any]) -> Attempt:
    """Grasp ``k`` (from 0) with ``plan``: a later grasp first releases the object and
    changes the hand when the plan's is another; the record's ``grasp`` is the first.

    Raises:
        MissedGrasp: the first grasp was not executed (the palm landed on the object, the
            hand was blocked on its way down or overlapped the object where it started).
    """
    world = trial.world
    trial.report(f"grasp {k + 1} with {plan.gripper}")
    with trial.phase("grasp"):
        if k > 0:
            released = world.release()
            if plan.gripper != world.gripper.name:
                world.remove_hand()
                world.add_hand(plan.gripper)
        outcome = world.execute_grasp(plan)
    shift_m, tilt_rad = object_motion(trial.obj.mesh, outcome.object_before, outcome.object_after)
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
    attempt = Attempt(k, plan, chosen_by, outcome, executed, shift_m, tilt_rad)
    if k == 0:
        trial.record.first_grasp(executed, outcome.object_after)
        if not outcome.executed:
            # Touching nothing as surely as a grasp that closed on air: look and grasp again.
            why = f"grasp not executed: {outcome.reason}"
            trial.record.unfused(attempt.to_json(), why)
            raise MissedGrasp(why, plan)
    return attempt


def _read_taxels(trial: Trial, attempt: Attempt) -> tuple[Contacts | None, str]:
    """The taxels ``attempt`` touched, and why it is not fused (``""``: it is); a first
    grasp not fused is the record's ``unfused_grasp``, a later one joins its
    ``unfused_grasps``.

    Raises:
        MissedGrasp: the first grasp touched nothing or one side only (its taxels, when
            any, are written to ``contacts.json`` for ``symfuse fuse``, as read).
    """
    k, plan = attempt.k, attempt.plan
    if not attempt.outcome.executed:
        why = f"grasp {k + 1} not executed: {attempt.outcome.reason}"
        trial.record.unfused(attempt.to_json(), why)
        return None, why
    with trial.phase("tactile"):
        contacts = trial.stages.tactile.read(trial.world, attempt.outcome)
    stop = unfused_reason(k, contacts, attempt.shift_m, attempt.tilt_rad)
    if stop:
        trial.record.unfused(attempt.to_json(contacts), stop)
        if k == 0:
            if len(contacts):
                with trial.phase("write"):
                    write_json(
                        trial.out_dir / "contacts.json", contacts_to_json([contacts], [plan])
                    )
            raise MissedGrasp(stop, plan)
    return contacts, stop


def _look_after(trial: Trial, look: Look, attempt: Attempt) -> AfterView | None:
    """The camera's view while the hand holds the object after ``attempt``
    (docs/after-view.md); None when ``trial.after_view`` is off."""
    if not trial.settings.after_view:
        return None
    trial.report(f"looking again after grasp {attempt.k + 1}")
    with trial.phase("after_view"):
        return look_after(
            trial.stages.sensor,
            trial.world,
            look.observation,
            look.cloud,
            attempt.outcome,
            attempt.plan,
        )


def _fuse(
    trial: Trial,
    look: Look,
    attempt: Attempt,
    init: SymmetryInit,
    grasps: tuple[Contacts, ...],
    views: tuple[AfterView | None, ...],
) -> Fused:
    """Fuse ``grasps`` (every grasp so far, ``attempt`` the last) from ``init``, with each
    grasp's after-view in ``views``, and score the estimate against the object as
    ``attempt`` left it."""
    trial.report(f"fusing {len(grasps)} grasp(s)")
    with trial.phase("estimator"):
        result = estimate_with(
            trial.stages.estimator, look.cloud, init, grasps, look.observation, views
        )
    with trial.phase("evaluation"):
        after = attempt.outcome.object_after
        truth = ground_truth(trial.obj, after, look.pose_seen, look.observation.calibration_error)
        centre = np.asarray(attempt.plan.T_robot_hand)[:2, 3]
        evaluated = [evaluate_stage(stage, truth, centre) for stage in result.stages]
        floor = deviation_floor(result.selected, truth)
    return Fused(init, result, truth, evaluated, after, grasps, floor)


def next_hands(world: World, planners: Planners, choice: HandChoice) -> dict[str, NextHand]:
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
            planner = planners(answer.planner)
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
    of a ``grasps`` entry before the estimate, and of ``result.json``'s ``unfused_grasp``
    and ``unfused_grasps`` (not executed, or touching too little to fuse)."""
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
    :func:`~pipeline.metrics.evaluation.opposing_contacts`). Nothing held the object against the
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


def _initial_state(trial: Trial, look: Look, plan: GraspPlan, contacts: Contacts) -> SymmetryInit:
    """Stage 0 from the proposal and the first grasp (the record's ``init``).

    Raises:
        StageFailure: the initialiser rejected every hypothesis.
    """
    with trial.phase("initialiser"):
        init = trial.stages.initialiser.refine(look.proposal, look.cloud, plan, contacts)
    trial.record.initial_state(init)
    if init.status != "ok":
        name = trial.config.choices["initialiser"]
        raise StageFailure(f"initialiser '{name}' rejected: {init.reason}")
    return init


def measurement_model(trial: Trial) -> MeasurementModel:
    """The taxel model the information score predicts with: the configured estimator's
    (:meth:`~pipeline.stages.Estimator.measurement_model`), else that of the first
    installed estimator that has one, with its configured parameters (whichever
    estimator fuses, the score predicts as a taxel-fusing estimator would)."""
    own = trial.stages.estimator.measurement_model()
    if own is not None:
        return own
    registry, params = trial.registry, trial.config.params["estimator"]
    for name in registry.names("estimator"):
        cls = registry.get("estimator", name).cls
        if cls.measurement_model is not Estimator.measurement_model:
            model = registry.create("estimator", name, to_toml(params.get(name, cls.Params())))
            return model.measurement_model()
    raise StageFailure("no installed estimator predicts taxels for the next-grasp score")


def grasp_to_json(
    attempt: Attempt, planner: str, contacts: Contacts, fused: Fused, known: Uncertainty
) -> dict[str, Any]:
    """One entry of ``result.json``'s ``grasps``: how the grasp was chosen and went, and
    the estimate after fusing it and every grasp before (each stage without its iteration
    trace, with its metrics against the object after this grasp)."""
    metrics = [stage_metrics for stage_metrics, _ in fused.evaluated]
    entries = estimate_entries(fused.result, metrics, trace=False)
    return {
        **attempt.to_json(contacts),
        "planner": planner,
        "status": fused.result.final.status,
        **selection_to_json(fused.result),
        "uncertainty": known.to_json(),
        "deviation_floor_m": None if fused.floor is None else fused.floor.as_dict(),
        "stages": entries["stages"],
    }
