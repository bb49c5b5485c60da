"""A Rerun recording (``.rrd``) of a finished run, built from the files the run wrote.

:func:`write_recording` reads a run folder (``symfuse trial``, ``fuse``, or a folder of
per-object runs with an ``objects.json``) and never re-runs anything, so ``--rerun`` and
``symfuse view`` give the same recording. What is missing from a folder (no camera for
``fuse``, no true mesh outside simulation) is left out.

Entities, all in the robot frame ``R`` (metres, z up); ``OBJ`` is ``world`` for a single run
and ``world/<folder>`` for each object of a multi-object run (its plots under
``plots/<folder>``):

=============================  ======================================================
``world/camera``               the believed camera pose ``T_robot_camera`` (Transform3D)
``world/camera/image``         pinhole intrinsics (OpenCV optical frame)
``world/camera/image/rgb``     colour image (``rgb.png``)
``world/camera/image/depth``   metric depth (``depth.npy``, millimetres, 0 = no return)
``OBJ/cloud``                  the segmented cloud
``OBJ/model``                  the completed model of the current stage, coloured by
                               distance to the true surface (0 mm blue, 30 mm red) when
                               the truth is known
``OBJ/plane``                  the symmetry plane of the current stage or iteration (moved
                               by the bias, so the model is symmetric about it), a
                               translucent quad
``OBJ/truth``                  the object's true mesh after the grasp (simulation)
``OBJ/hand/<link>``            the hand's link shapes at the grasp (URDF, joint positions
                               after closing)
``OBJ/after_view``             what the camera saw while the hand held the object
                               (``after_depth.npy`` of each grasp, within 50 mm of the
                               cloud; docs/after-view.md)
``OBJ/taxels``                 the taxels in contact, coloured by their distance to the
                               current model (0 mm green, 10 mm red)
``plots/plane/theta_deg``,     the IEKF state after every iteration
``plots/plane/offset_mm``,
``plots/bias/yaw_deg``,
``plots/bias/{x,y,z}_mm``
``plots/gates/taxels``,        taxels with some correspondence weight, points inside
``plots/gates/points``         some gate, per iteration
``log``                        one line per step saying what it shows
=============================  ======================================================

One timeline, ``step``, runs over the pipeline (camera, segmentation, Stage 0, grasp), each
IEKF iteration of Stage 1, Stage 1's result, each iteration of Stage 2 and its result.
Scrubbing it shows the plane and the bias converging; between results the model stays at the
last finished stage (the iterations record the state, not the points).

One module because the table above and the code that fills it belong together: the
recorder reads each file of a run folder once and logs it under its entities on that one
timeline.
"""

from __future__ import annotations

import importlib
import os
import uuid
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from pipeline.errors import InputError, MissingExtraError
from pipeline.io.camera_file import CameraFile, read_camera
from pipeline.io.captures import Capture, read_depth_image
from pipeline.io.formats import read_cloud, read_contacts, read_json
from pipeline.metrics import nearest_distances, plane_after_bias, point_to_mesh_distances
from pipeline.reports.trial_pictures import DEVIATION_CMAP, DEVIATION_MAX_M
from pipeline.types import Bias, Contacts, SymmetryPlane
from pipeline.viz.layout import blueprint, plots_path
from pipeline.viz.shapes import plane_quad

#: File name of the recording inside a run folder.
RECORDING_NAME = "recording.rrd"


#: Taxel colours span 0 to this distance from the model (m).
TAXEL_RESIDUAL_MAX_M = 0.010


PLANE_RGBA = (255, 190, 0, 90)


CLOUD_RGB = (90, 150, 230)
#: The after-view's points: the same camera, later, in orange.
AFTER_VIEW_RGB = (240, 150, 60)
#: The after-view is shown this far around the first view's cloud (m).
AFTER_VIEW_MARGIN_M = 0.05


MODEL_RGB = (240, 140, 40)


TRUTH_RGBA = (200, 200, 200, 110)


HAND_RGBA = (120, 120, 130, 255)


def rerun_module() -> ModuleType:
    """The ``rerun`` module; :class:`MissingExtraError` naming the extra when absent."""
    try:
        return importlib.import_module("rerun")
    except ImportError:
        raise MissingExtraError(
            "the Rerun recording needs the viz extra: pip install 'symfuse[viz]'"
        ) from None


def run_folders(run_dir: Path) -> list[tuple[Path, str]]:
    """The run folders under ``run_dir`` with the entity name of each: ``run_dir`` itself
    (``"world"``), or each sub-folder holding a ``result.json`` (``"world/<name>"``).

    Raises:
        InputError: ``run_dir`` holds no run.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        what = "a file, not a run's folder" if run_dir.exists() else "no such folder"
        raise InputError(f"{run_dir}: {what}")
    if (run_dir / "result.json").is_file():
        return [(run_dir, "world")]
    objects = sorted(p.parent for p in run_dir.glob("*/result.json"))
    if not objects:
        raise InputError(f"{run_dir}: no result.json here or in its sub-folders (not a run)")
    return [(folder, f"world/{folder.name}") for folder in objects]


def write_recording(run_dir: Path, out_path: Path | None = None) -> Path:
    """Build the recording of the run in ``run_dir`` (module doc) and write it to
    ``out_path`` (default ``run_dir/recording.rrd``); returns the path written."""
    rr = rerun_module()
    run_dir = Path(run_dir)
    runs = [(_RunFiles.load(folder), entity) for folder, entity in run_folders(run_dir)]
    camera = _RunCamera.load(run_dir)
    out_path = Path(out_path) if out_path is not None else run_dir / RECORDING_NAME
    # Written beside its place and moved there at the end: a recording that fails half-way
    # leaves no half file (nor replaces a good one).
    partial = out_path.with_name(f".{out_path.name}.partial")
    recording = rr.RecordingStream("symfuse", recording_id=str(uuid.uuid4()))
    plots = {entity: plots_path(entity) for _, entity in runs}
    position = None if camera is None else camera.position_m
    try:
        recording.save(partial, default_blueprint=blueprint(runs, position, list(plots.values())))
        timeline = _Timeline(rr, recording)
        recording.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        if camera is not None:
            timeline.next("camera: depth and colour image, intrinsics and pose")
            camera.log(rr, recording)
        for files, entity in runs:
            _RunRecorder(rr, recording, timeline, files, entity, plots[entity]).log()
        recording.flush()
        recording.disconnect()
        os.replace(partial, out_path)
    finally:
        partial.unlink(missing_ok=True)
    return out_path


def read_run_json(path: Path) -> dict[str, Any]:
    """A run's JSON object (``result.json``, ``camera.json``)."""
    document = read_json(path)
    if not isinstance(document, dict):
        raise InputError(f"{path}: the top level must be a JSON object")
    return document


class _Timeline:
    """The ``step`` timeline: each step logs one line to ``log``."""

    def __init__(self, rr: ModuleType, recording) -> None:
        self.rr, self.recording, self.step = rr, recording, -1

    def next(self, text: str) -> None:
        self.step += 1
        self.recording.set_time("step", sequence=self.step)
        self.recording.log("log", self.rr.TextLog(text))


@dataclass(frozen=True)
class _RunCamera:
    """A run's ``camera.json``, with its ``depth.npy`` and ``rgb.png`` when there, read and
    checked as ``symfuse fuse`` reads them."""

    camera: CameraFile
    capture: Capture | None

    @classmethod
    def load(cls, run_dir: Path) -> _RunCamera | None:
        camera_path = run_dir / "camera.json"
        if not camera_path.is_file():
            return None
        depth_path = run_dir / "depth.npy"
        capture = read_depth_image(depth_path, camera_path, None) if depth_path.is_file() else None
        return cls(read_camera(camera_path), capture)

    @property
    def position_m(self) -> np.ndarray | None:
        """The camera's optical centre in R, None when the run has no robot frame."""
        T = self.camera.T_robot_camera
        return None if T is None else T[:3, 3]

    def log(self, rr: ModuleType, recording) -> None:
        k = self.camera.intrinsics
        T = self.camera.T_robot_camera
        if T is not None:
            recording.log("world/camera", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))
        recording.log(
            "world/camera/image",
            rr.Pinhole(
                image_from_camera=[[k.fx, 0, k.cx], [0, k.fy, k.cy], [0, 0, 1]],
                width=k.width,
                height=k.height,
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.1,
            ),
        )
        if self.capture is None:
            return
        if self.capture.rgb is not None:
            recording.log("world/camera/image/rgb", rr.Image(self.capture.rgb))
        depth_m = self.capture.depth_m
        depth_mm = np.where(np.isfinite(depth_m), np.round(depth_m * 1e3), 0.0)
        recording.log(
            "world/camera/image/depth", rr.DepthImage(depth_mm.astype(np.uint16), meter=1000.0)
        )


@dataclass(frozen=True)
class _RunFiles:
    """What one run folder holds; None (or empty) where a file is missing."""

    folder: Path
    document: dict[str, Any]
    cloud: np.ndarray | None
    models: dict[int, np.ndarray]
    truth: Any
    grasps: tuple[Contacts, ...]
    plans: tuple[Any, ...]
    after_views: tuple[np.ndarray, ...] = ()

    @property
    def reference(self) -> np.ndarray | None:
        """The points the plane quads are sized on: Stage 0's model, else the cloud."""
        points = self.models.get(0, self.cloud)
        return points if points is not None and len(points) else None

    @classmethod
    def load(cls, folder: Path) -> _RunFiles:
        import trimesh

        document = read_run_json(folder / "result.json")
        inputs = document.get("inputs", {})
        cloud_path = _existing(folder / "cloud.ply", inputs.get("cloud"))
        contacts_path = _existing(folder / "contacts.json", inputs.get("contacts"))
        recorded = read_contacts(contacts_path) if contacts_path else None
        truth_path = folder / "object_final.ply"
        models = {
            stage["stage"]: read_cloud(path).points
            for stage in document.get("stages", [])
            if (path := folder / f"completed_stage{stage['stage']}.ply").is_file()
        }
        cloud = read_cloud(cloud_path).points if cloud_path else None
        return cls(
            folder=folder,
            document=document,
            cloud=cloud,
            models=models,
            truth=trimesh.load(truth_path, force="mesh") if truth_path.is_file() else None,
            grasps=recorded.contacts if recorded else (),
            plans=recorded.plans if recorded else (),
            after_views=_after_view_points(recorded, cloud) if recorded else (),
        )


def _after_view_points(recorded, cloud: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """Each grasp's after-view back-projected (its ``camera.json`` beside it), within
    :data:`AFTER_VIEW_MARGIN_M` of the cloud's bounding box; the grasps with one that is
    there and placed in the robot frame."""
    from pipeline.perception.depth import backproject_depth

    if cloud is None or not len(cloud):
        return ()
    low, high = cloud.min(axis=0) - AFTER_VIEW_MARGIN_M, cloud.max(axis=0) + AFTER_VIEW_MARGIN_M
    views = []
    for path in recorded.after_depth:
        if path is None or not path.is_file():
            continue
        capture = read_depth_image(path, None, None)
        if capture.T_robot_camera is None:
            continue
        points, _ = backproject_depth(capture.depth_m, capture.intrinsics, capture.T_robot_camera)
        views.append(points[np.all((points >= low) & (points <= high), axis=1)])
    return tuple(views)


def _existing(local: Path, recorded: str | None) -> Path | None:
    """``local`` if present, else the input path the run recorded if that still exists."""
    if local.is_file():
        return local
    if recorded and Path(recorded).is_file():
        return Path(recorded)
    return None


def _colours(values: np.ndarray, cmap: str, top: float) -> np.ndarray:
    import matplotlib

    rgba = matplotlib.colormaps[cmap](np.clip(values / top, 0.0, 1.0))
    return (rgba[:, :3] * 255).astype(np.uint8)


class _RunRecorder:
    """Logs one run folder's steps (module doc) under ``entity`` and ``plots``."""

    def __init__(self, rr, recording, timeline, files: _RunFiles, entity: str, plots: str):
        self.rr, self.recording, self.timeline = rr, recording, timeline
        self.files, self.entity, self.plots = files, entity, plots
        stages = files.document.get("stages", [])
        self.stages = {stage["stage"]: stage for stage in stages}
        self.extent = files.reference
        self.taxels = (
            np.vstack([grasp.positions for grasp in files.grasps]) if files.grasps else None
        )

    def log(self) -> None:
        files, name = self.files, self.files.folder.name
        if files.cloud is not None:
            self.timeline.next(f"{name}: segmented cloud, {len(files.cloud)} points")
            self.recording.log(
                f"{self.entity}/cloud",
                self.rr.Points3D(files.cloud, colors=CLOUD_RGB, radii=0.0008),
            )
        for k in sorted(self.stages):
            if k > 0:
                self._log_iterations(k)
            self.timeline.next(f"{name}: Stage {k} ({self.stages[k].get('status', '?')})")
            self._log_stage(k)
            if k == 0:
                self._log_grasp()

    def _log_stage(self, k: int) -> None:
        stage = self.stages[k]
        plane, bias = _plane(stage["plane"]), _bias(stage["bias"])
        self._log_plane(plane_after_bias(plane, bias))
        model = self.files.models.get(k)
        if model is None:
            return
        truth = self.files.truth
        if truth is not None:
            distances = point_to_mesh_distances(model, truth.vertices, truth.faces)
            colours = _colours(distances, DEVIATION_CMAP, DEVIATION_MAX_M)
        else:
            colours = np.tile(np.array(MODEL_RGB, dtype=np.uint8), (len(model), 1))
        self.recording.log(
            f"{self.entity}/model", self.rr.Points3D(model, colors=colours, radii=0.001)
        )
        if k > 0:
            self._log_taxels(model)

    def _log_taxels(self, model: np.ndarray) -> None:
        if self.taxels is None:
            return
        residual = nearest_distances(self.taxels, model)
        self.recording.log(
            f"{self.entity}/taxels",
            self.rr.Points3D(
                self.taxels,
                colors=_colours(residual, "RdYlGn_r", TAXEL_RESIDUAL_MAX_M),
                radii=0.0015,
            ),
        )

    def _log_plane(self, plane: SymmetryPlane) -> None:
        if self.extent is None:
            return
        corners = plane_quad(plane, self.extent)
        self.recording.log(
            f"{self.entity}/plane",
            self.rr.Mesh3D(
                vertex_positions=corners,
                # Both windings, so the quad shows from either side.
                triangle_indices=[[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]],
                albedo_factor=PLANE_RGBA,
            ),
        )

    def _log_iterations(self, k: int) -> None:
        trace = self.stages[k].get("trace", [])
        for number, state in enumerate(trace, start=1):
            self.timeline.next(
                f"{self.files.folder.name}: Stage {k} iteration {number} of {len(trace)} "
                f"(grasp {state['grasp'] + 1}), {state['active_taxels']} taxels, "
                f"{state['active_points']} points in gates"
            )
            plane, bias = _plane(state["plane"]), _bias(state["bias"])
            self._log_plane(plane_after_bias(plane, bias))
            values = {
                "plane/theta_deg": plane.theta_rad * 180.0 / np.pi,
                "plane/offset_mm": plane.offset_m * 1e3,
                "bias/yaw_deg": bias.yaw_rad * 180.0 / np.pi,
                "bias/x_mm": bias.translation_m[0] * 1e3,
                "bias/y_mm": bias.translation_m[1] * 1e3,
                "bias/z_mm": bias.translation_m[2] * 1e3,
                "gates/taxels": state["active_taxels"],
                "gates/points": state["active_points"],
            }
            for path, value in values.items():
                self.recording.log(f"{self.plots}/{path}", self.rr.Scalars(float(value)))

    def _log_grasp(self) -> None:
        files, name = self.files, self.files.folder.name
        if not files.grasps and files.truth is None:
            return
        text = "the true object" if not files.grasps else f"grasp, {len(self.taxels)} taxels"
        self.timeline.next(f"{name}: {text} (taxel colour: distance to the Stage 0 model)")
        if files.truth is not None:
            self.recording.log(
                f"{self.entity}/truth",
                self.rr.Mesh3D(
                    vertex_positions=files.truth.vertices,
                    triangle_indices=files.truth.faces,
                    vertex_normals=files.truth.vertex_normals,
                    albedo_factor=TRUTH_RGBA,
                ),
            )
        if 0 in files.models:
            self._log_taxels(files.models[0])
        if files.after_views:
            self.recording.log(
                f"{self.entity}/after_view",
                self.rr.Points3D(np.vstack(files.after_views), colors=AFTER_VIEW_RGB, radii=0.0008),
            )
        for link, (vertices, faces, normals) in self._hand_links().items():
            self.recording.log(
                f"{self.entity}/hand/{link}",
                self.rr.Mesh3D(
                    vertex_positions=vertices,
                    triangle_indices=faces,
                    vertex_normals=normals,
                    albedo_factor=HAND_RGBA,
                ),
            )

    def _hand_links(self) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Each hand link's shapes in frame R at the last grasp, from the URDF's forward
        kinematics; empty when the hand or its pose is unknown."""
        plan = self.files.plans[-1] if self.files.plans else None
        # A trial records every grasp's execution in "grasps" (fuse: their taxel counts).
        executed = self.files.document.get("grasps") or [None]
        grasp = executed[-1] if isinstance(executed[-1], dict) else None
        grasp = grasp or self.files.document.get("grasp", {})
        if plan is None:
            return {}
        T_robot_hand = np.asarray(grasp.get("T_robot_hand", plan.T_robot_hand), dtype=float)
        world = _world_class(self.files.document)
        if world is None:
            return {}
        return world.hand_meshes(plan.gripper, grasp.get("joint_positions"), T_robot_hand, plan)


def _world_class(document: dict[str, Any]):
    """The installed world class a run was made in (a run from before the world was a
    stage: the shipped default), or None when it is not installed."""
    from pipeline.config import load_config
    from pipeline.errors import PluginError
    from pipeline.registry import load_registry

    registry = load_registry()
    name = document.get("stages_used", {}).get("world") or load_config(registry).choices["world"]
    try:
        return registry.get("world", name).cls
    except PluginError:
        return None


def _plane(document: dict[str, Any]) -> SymmetryPlane:
    return SymmetryPlane.from_normal(np.asarray(document["normal"]), document["offset"])


def _bias(document: dict[str, Any]) -> Bias:
    return Bias(document["yaw"], document["translation"], document["pivot"])
