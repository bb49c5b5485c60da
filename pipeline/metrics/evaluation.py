"""Scoring an estimate against the ground truth of a simulated trial (docs/method.md §6).

The completed model of a stage lives in the frame where the hand touched the object, so it
is compared with the object's true pose *after* the grasp, and its symmetry plane is the
estimated plane moved by the estimated bias (:func:`pipeline.metrics.plane_after_bias`).

Beside the paper's deviation and measures, every stage gets the shape-completion scores of
the recent literature: symmetric Chamfer distance, F-score at 2 and 5 mm and the volumetric
IoU of the completed model's convex hull with the true solid (:mod:`pipeline.metrics`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.metrics import (
    DeviationSummary,
    MeshSurface,
    SolidGrid,
    box_thickness,
    fit_circle_taubin,
    grid_order,
    hull_iou,
    nearest_distances,
    plane_after_bias,
    sample_surface,
    side_wall,
    solid_grid,
    solid_share_inside,
    surface_scores,
)
from pipeline.symmetry.scoring import symmetry_errors
from pipeline.types import Bias, Contacts, ObjectPose, StageEstimate, Symmetry, SymmetryPlane

if TYPE_CHECKING:
    import trimesh

    from pipeline.asset.model import ModelAsset


@dataclass(frozen=True)
class GroundTruth:
    """What a simulated trial knows about the object after the grasp, frame R.

    Attributes:
        vertices, faces: the object's mesh in its true pose after the grasp (m).
        symmetry: ``"planar"``, ``"rotational"`` or ``"none"``.
        plane: the true mirror plane after the grasp (planar objects), else None.
        axis_xy_m: a point on the true symmetry axis/plane (the object origin, or the
            plane's point nearest it for a plane off the origin), frame R.
        thickness_m: true thickness for box-like objects, else None.
        diameter_m: true diameter for cylinders, else None.
        cloud_motion: ``(4, 4)`` the rigid motion that takes the camera's cloud onto the
            object after the grasp (the object's motion since the view, after undoing the
            camera's calibration error): the bias the estimator should find. None when the
            sensor does not know its calibration error.
        symmetries: every true mirror plane and rotation axis after the grasp
            (:mod:`pipeline.symmetry`), frame R; the estimated plane is scored against the
            nearest (``symmetry_angle_error_deg``, ``symmetry_offset_error_mm``).

    The surface samples, the solid and the mesh's distance structure every stage is scored
    against are computed once, on first use.
    """

    vertices: np.ndarray
    faces: np.ndarray
    symmetry: str
    plane: SymmetryPlane | None
    axis_xy_m: np.ndarray
    thickness_m: float | None = None
    diameter_m: float | None = None
    cloud_motion: np.ndarray | None = None
    symmetries: tuple[Symmetry, ...] = ()

    @functools.cached_property
    def surface_samples(self) -> np.ndarray:
        """``(SURFACE_SAMPLES, 3)`` points on the true surface but the face the object stands
        on (fixed seed: the same points for every stage and every run)."""
        return sample_surface(self.vertices, self.faces, SURFACE_SAMPLES, seed=0)

    @functools.cached_property
    def _sample_order(self) -> np.ndarray:
        """The surface samples' indices in :func:`grid_order` (near samples one after
        another)."""
        return grid_order(self.surface_samples)

    def sample_distances(self, distances: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """``distances(surface_samples)`` (one value per sample, m), each sample's value as
        that function gives it, asked in :func:`grid_order`: a k-d tree's or a mesh's
        hierarchy answers near queries one after another from what it has in cache (about
        a third faster for 20,000 samples)."""
        order = self._sample_order
        result = np.empty(len(order))
        result[order] = distances(self.surface_samples[order])
        return result

    @functools.cached_property
    def surface(self) -> MeshSurface:
        """The true mesh, for the distances of every stage's points and samples."""
        return MeshSurface(self.vertices, self.faces)

    @functools.cached_property
    def solid(self) -> SolidGrid:
        """The true object's solid on a grid of cells (for the volumetric IoU)."""
        return solid_grid(self.vertices, self.faces)


#: Points sampled on the true surface for recall and Chamfer distance: the recall's standard
#: error is below 0.4 percentage points.
SURFACE_SAMPLES = 20_000


def plane_errors(estimated: SymmetryPlane, truth: GroundTruth) -> dict[str, float]:
    """Orientation error (deg, modulo 180) and offset error (mm) of a symmetry plane.

    The offset error is the distance of the true plane's anchor (the object origin) to the
    estimated plane; for rotational objects only that is defined.
    """
    errors = {
        "plane_offset_error_mm": float(
            abs(estimated.normal[:2] @ truth.axis_xy_m - estimated.offset_m) * 1e3
        )
    }
    if truth.plane is not None:
        difference = (estimated.theta_rad - truth.plane.theta_rad) % np.pi
        errors["plane_angle_error_deg"] = float(np.degrees(min(difference, np.pi - difference)))
    return errors


def evaluate_stage(
    stage: StageEstimate, truth: GroundTruth, grasp_centre_xy_m: np.ndarray
) -> tuple[dict[str, Any], np.ndarray]:
    """Metrics of one stage and each completed point's distance to the true surface (m).

    The metrics are the deviation summary (m), the plane errors (against the paper's one
    vertical plane, and against the nearest of every true symmetry), the shape scores
    (:func:`shape_scores`), and the object's measure (thickness or diameter, with the error
    in mm and percent) where defined: thickness by robust lines through the grasp centre,
    diameter by a circle fit to the side wall.
    """
    plane = plane_after_bias(stage.plane, stage.bias)
    distances = truth.surface.distances(stage.completed)
    centre = truth.vertices.min(axis=0) / 2.0 + truth.vertices.max(axis=0) / 2.0
    metrics: dict[str, Any] = {
        "deviation_m": DeviationSummary.from_distances(distances).as_dict(),
        **plane_errors(plane, truth),
        **symmetry_errors(_moved_symmetry(stage, plane), truth.symmetries, centre),
        **shape_scores(stage.completed, distances, truth),
    }
    if truth.cloud_motion is not None:
        metrics.update(bias_errors(stage.bias, stage.covariance, plane, truth.cloud_motion))
    if truth.thickness_m is not None:
        try:
            fit = box_thickness(stage.completed, plane, grasp_centre_xy_m)
        except ValueError as exc:
            metrics["thickness_error"] = str(exc)
        else:
            metrics.update(_measure("thickness", fit.thickness_m, truth.thickness_m))
            metrics["side_angle_deg"] = float(np.degrees(fit.angle_rad))
    if truth.diameter_m is not None:
        circle = fit_circle_taubin(side_wall(stage.completed))
        metrics.update(_measure("diameter", circle.diameter_m, truth.diameter_m))
    return metrics, distances


def _moved_symmetry(stage: StageEstimate, moved_plane: SymmetryPlane) -> Symmetry:
    """The stage's mirror plane after its bias: the leaning plane it fused, else the
    vertical ``moved_plane``."""
    if stage.symmetry is None:
        return Symmetry.from_plane(moved_plane)
    return stage.symmetry.transformed(stage.bias.transform)


def bias_errors(
    bias: Bias, covariance: np.ndarray, plane: SymmetryPlane, motion: np.ndarray
) -> dict[str, float]:
    """The estimated bias against the true one, and the standard deviations its covariance
    claimed.

    The true bias with the estimate's pivot ``c`` is the yaw of ``motion`` and the
    displacement it gives ``c``. The translation error is split along the normal of
    ``plane`` (the estimated plane after the bias: the direction opposed pads press,
    ``across``) and horizontally within it (``along``, which pads on a flat side hardly
    see). ``bias_nees`` is the normalised estimation error squared ``e^T P_b^-1 e`` over the
    four bias components ``(yaw, x, y, z)``: a covariance that tells the truth makes it
    chi-square with 4 degrees of freedom (mean 4, below
    :data:`pipeline.experiments.paper_report.BIAS_NEES_BOUND` 99 % of the time); inf when
    the covariance claims a component exactly known that is not.

    Args:
        bias: the estimated bias (its pivot is used for the truth as well).
        covariance: ``(6, 6)`` covariance of ``(b_theta, b_x, b_y, b_z, m_r, m_theta)``.
        plane: the estimated plane after the bias, frame R.
        motion: ``(4, 4)`` the true motion from the camera's cloud to the object.
    """
    pivot = bias.pivot_m
    true_yaw = float(np.arctan2(motion[1, 0], motion[0, 0]))
    true_shift = motion[:3, :3] @ pivot + motion[:3, 3] - pivot
    yaw_error = float(np.pi - (np.pi - (bias.yaw_rad - true_yaw)) % (2.0 * np.pi))
    error = np.concatenate([[yaw_error], bias.translation_m - true_shift])
    block = np.asarray(covariance, dtype=float)[:4, :4]
    normal = np.append(plane.normal[:2], 0.0)
    along = np.array([-normal[1], normal[0], 0.0])
    metrics = {
        "bias_yaw_error_deg": float(np.degrees(yaw_error)),
        "bias_yaw_std_deg": float(np.degrees(np.sqrt(block[0, 0]))),
    }
    for name, direction in (("across", normal), ("along", along)):
        metrics[f"bias_{name}_error_mm"] = float(direction @ error[1:]) * 1e3
        metrics[f"bias_{name}_std_mm"] = float(np.sqrt(direction @ block[1:, 1:] @ direction)) * 1e3
    try:
        metrics["bias_nees"] = float(error @ np.linalg.solve(block, error))
    except np.linalg.LinAlgError:
        metrics["bias_nees"] = math.inf
    return metrics


def shape_scores(
    completed: np.ndarray, distances_m: np.ndarray, truth: GroundTruth
) -> dict[str, float]:
    """Chamfer distance (mm), precision, recall and F-score at 2 and 5 mm, and ``iou``.

    The model-to-truth direction uses each completed point's exact distance to the true
    surface (``distances_m``, as the deviation does); the truth-to-model direction each
    surface sample's distance to the nearest completed point. ``iou`` is the volumetric IoU
    of the completed model's convex hull with the true solid.
    """
    to_model = truth.sample_distances(lambda samples: nearest_distances(samples, completed))
    scores = surface_scores(distances_m, to_model)
    scores["iou"] = hull_iou(completed, truth.solid)
    return scores


def mesh_scores(mesh: trimesh.Trimesh, truth: GroundTruth) -> dict[str, float]:
    """The shape scores of :func:`shape_scores` for a closed mesh of the model (frame R):
    ``mesh_chamfer_mm``, ``mesh_fscore_2mm`` ... and ``mesh_iou``.

    The model-to-truth direction uses :data:`SURFACE_SAMPLES` points drawn on the mesh
    (its base included: the truth's is part of the true surface), the truth-to-model one
    each true surface sample's exact distance to the mesh; ``mesh_iou`` counts the true
    solid's cells inside the mesh against the mesh's exact volume.
    """
    from pipeline.asset.mass import signed_volume

    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    samples = sample_surface(vertices, faces, SURFACE_SAMPLES, seed=0, skip_support=False)
    surface = MeshSurface(vertices, faces)
    scores = surface_scores(
        truth.surface.distances(samples), truth.sample_distances(surface.distances)
    )
    solid = truth.solid
    inside_share = solid_share_inside(surface, solid)
    volume = abs(signed_volume(mesh))
    shared = min(inside_share * solid.volume_m3, volume)
    union = volume + solid.volume_m3 - shared
    scores["iou"] = shared / union if union > 0.0 else 0.0
    return {f"mesh_{name}": value for name, value in scores.items()}


def model_scores(model: ModelAsset, truth: GroundTruth) -> dict[int, dict[str, float]]:
    """Stage -> :func:`mesh_scores` of its mesh, moved into frame R."""
    return {
        stage: mesh_scores(mesh.copy().apply_transform(model.T_robot_object), truth)
        for stage, mesh in model.meshes.items()
    }


def _measure(name: str, measured_m: float, true_m: float) -> dict[str, float]:
    error_m = measured_m - true_m
    return {
        f"{name}_mm": measured_m * 1e3,
        f"{name}_error_mm": error_m * 1e3,
        f"{name}_error_pct": abs(error_m) / true_m * 100.0,
    }


def object_motion(
    mesh: trimesh.Trimesh, before: ObjectPose, after: ObjectPose
) -> tuple[float, float]:
    """How far a grasp moved the object: the displacement of the centre of its mesh's
    bounding box (m; the mesh origin may lie anywhere, e.g. off a scan) and the angle its
    up axis tilted (rad)."""
    centre = np.append(np.asarray(mesh.bounds).mean(axis=0), 1.0)
    shift = (after.transform @ centre - before.transform @ centre)[:3]
    cosine = float(np.clip(after.transform[:3, 2] @ before.transform[:3, 2], -1.0, 1.0))
    return float(np.linalg.norm(shift)), float(np.arccos(cosine))


def object_turn(before: ObjectPose, after: ObjectPose) -> float:
    """The angle a grasp turned the object about the vertical (rad, counter-clockwise seen
    from above, in (-pi, pi]): the change of the heading of its x axis projected on the
    table. A round object turning in the jaws keeps its centre, so :func:`object_motion`
    does not show it; the estimator's bias yaw should."""
    headings = [np.arctan2(pose.transform[1, 0], pose.transform[0, 0]) for pose in (before, after)]
    return float(np.pi - (np.pi - (headings[1] - headings[0])) % (2.0 * np.pi))


def opposing_contacts(contacts: Contacts, tolerance_deg: float = 30.0) -> bool:
    """Whether the contacts press on opposing sides: the horizontal mean normals of the
    touching pads are not all within an arc narrower than ``180 - tolerance_deg`` deg, i.e.
    the largest angular gap between them is at most ``180 + tolerance_deg`` (two antipodal
    pads: 180; three pads 120 deg apart: 120; a single pad: 360)."""
    bearings = []
    for pad in np.unique(contacts.pads):
        normal = contacts.normals[contacts.pads == pad].mean(axis=0)
        if np.hypot(normal[0], normal[1]) > 1e-6:
            bearings.append(np.arctan2(normal[1], normal[0]))
    if len(bearings) < 2:
        return False
    ordered = np.sort(bearings)
    gaps = np.diff(np.append(ordered, ordered[0] + 2.0 * np.pi))
    return bool(np.degrees(gaps.max()) <= 180.0 + tolerance_deg)


def one_sided_grasps(grasps: Sequence[Contacts]) -> list[int]:
    """The numbers (from 1) of the grasps whose taxels do not press from opposing sides
    (:func:`opposing_contacts`): they touched one side only, or nothing. Their pads may have
    pushed the object by an amount no taxel measures, which a trial does not fuse
    (docs/method.md §11)."""
    return [k for k, contacts in enumerate(grasps, start=1) if not opposing_contacts(contacts)]
