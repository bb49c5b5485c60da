"""One full simulated grasp trial, from the camera to the evaluated estimate.

    world -> sensor -> segmenter -> initialiser.propose -> planner (and hand choice)
      -> grasp -> tactile -> initialiser.refine -> estimator -> evaluation

The configured world (a stage like the others, :class:`pipeline.stages.World`) builds the
scene; it is sensed before its hand is chosen (:mod:`pipeline.hand_choice`) among the hands
the world offers, and the chosen hand is then added to it.

Every file the trial writes goes into one output folder (see :data:`TRIAL_FILES`); the
stages are timed one by one, and the resolved config is written next to the results.
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
from .camera_file import camera_to_json
from .catalogue import CatalogueObject, load_object
from .config import Config
from .errors import StageFailure, SymfuseError
from .evaluation import GroundTruth, evaluate_stage, object_motion
from .formats import (
    bias_to_json,
    contacts_to_json,
    estimate_to_json,
    plan_to_json,
    plane_to_json,
    selection_to_json,
    write_cloud,
    write_completed_clouds,
    write_json,
)
from .hand_choice import choice_to_json, choose_grasp
from .registry import StageRegistry
from .runner import estimate
from .types import EstimateResult, ObjectPose, SceneSetup, SymmetryInit, SymmetryPlane

#: The pictures a trial draws unless ``trial.pictures = false`` (VC adds ``vc_scores.png``).
PICTURE_FILES = ("rgb.png", "depth.png", "topdown.png", "deviation.png")
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


def ground_truth(obj: CatalogueObject, pose_after: ObjectPose) -> GroundTruth:
    """The object's truth in frame R after the grasp."""
    T = pose_after.transform
    vertices = np.asarray(obj.mesh.vertices) @ T[:3, :3].T + T[:3, 3]
    plane = None
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
        axis_xy_m=T[:2, 3].copy(),
        thickness_m=dims.get("thickness") if obj.kind == "box" else None,
        diameter_m=dims.get("diameter") if obj.kind == "cylinder" else None,
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
    from .plots import DeviationPanel, deviation_heatmap, plot_cloud_with_plane, plot_vc_scores

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
    obj = load_object(settings.object, units=settings.units)
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
    """The body of :func:`run_trial`: simulate, estimate, evaluate, write."""
    from .images import save_depth, save_rgb

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
        pose_before = world.object_pose()
        document["object_pose_before"] = pose_to_json(pose_before)
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
        document["points"] = len(cloud)
        report("initialising and planning")
        with timer.phase("initialiser"):
            proposal = stages["initialiser"].propose(cloud, observation)
        with timer.phase("planner"):
            grippers = {name: world.gripper_spec(name) for name in world.hands}
            choice = choose_grasp(
                config, registry, cloud, proposal, grippers, observation.table_height_m
            )
        plan = choice.plan
        document["gripper"] = choice.answer.gripper
        document["hand"] = choice_to_json(choice)
        if choice.answer.planner:
            document["stages_used"]["planner"] = choice.answer.planner
        document["plan"] = plan_to_json(plan)
        if plan.status != "ok":
            if not choice.answer.planner:
                raise StageFailure(plan.reason)
            raise StageFailure(f"grasp planner '{choice.answer.planner}' refused: {plan.reason}")
        report(f"grasping with {plan.gripper}")
        with timer.phase("grasp"):
            world.add_hand(plan.gripper)
            outcome = world.execute_grasp(plan)
        document["object_pose_after"] = pose_to_json(outcome.object_after)
        shift_m, tilt_rad = object_motion(obj.mesh, outcome.object_before, outcome.object_after)
        document["grasp"] = {
            "executed": outcome.executed,
            "aperture_m": outcome.aperture_m,
            "joint_positions": outcome.joint_positions,
            "T_robot_hand": np.asarray(outcome.T_robot_hand).tolist(),
            "reason": outcome.reason,
            "object_shift_mm": 1e3 * shift_m,
            "object_tilt_deg": float(np.degrees(tilt_rad)),
        }
        if not outcome.executed:
            raise StageFailure(f"grasp not executed: {outcome.reason}")
        with timer.phase("tactile"):
            contacts = stages["tactile"].read(world, outcome)
        with timer.phase("write"):
            write_json(out_dir / "contacts.json", contacts_to_json([contacts], [plan]))
            truth = ground_truth(obj, outcome.object_after)
            mesh_after = obj.mesh.copy().apply_transform(outcome.object_after.transform)
            mesh_after.export(out_dir / "object_final.ply")
        document["taxels_in_contact"] = len(contacts)
    finally:
        world.close()

    report("estimating")
    with timer.phase("initialiser"):
        init = stages["initialiser"].refine(proposal, cloud, plan, contacts)
    document["init"] = {
        "plane": plane_to_json(init.plane),
        "bias": bias_to_json(init.bias),
        "status": init.status,
        "hypotheses": [
            {**plane_to_json(h.plane), "score": h.score, "violations": h.violations}
            for h in init.hypotheses[:20]
        ],
    }
    if init.status != "ok":
        raise StageFailure(f"initialiser '{config.choices['initialiser']}' rejected: {init.reason}")
    with timer.phase("estimator"):
        result = estimate(config, registry, cloud, init, [contacts], observation)

    report("evaluating")
    with timer.phase("evaluation"):
        grasp_centre = np.asarray(plan.T_robot_hand)[:2, 3]
        evaluated = [evaluate_stage(stage, truth, grasp_centre) for stage in result.stages]
        metrics = [stage_metrics for stage_metrics, _ in evaluated]
    with timer.phase("write"):
        write_completed_clouds(out_dir, result)
    if settings.pictures:
        with timer.phase("pictures"):
            draw_pictures(out_dir, config, cloud.points, init, result, evaluated, truth)
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
