"""Completing every object of one depth view: ``symfuse complete``.

    sensor.observe -> segmenter.segment_objects -> (per selected object)
      initialiser.propose [-> initialiser.refine -> estimator.estimate, with contacts]

Objects that come within a few pixels of the edge of the view are set aside (they may
continue out of sight, so their mirror image would be wrong). The rest are numbered
largest first. When the sensor built the robot frame on the support plane
(``DepthObservation.frame_from_support``), its origin is moved below the centroid of the
largest object, so a frame that is otherwise only a convention is tied to the paper's
object; contacts for fusion are given in that frame.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.config import Config
from pipeline.errors import ConfigError, StageFailure
from pipeline.perception.principal_axes import table_axes
from pipeline.perception.segmentation import outside_view, touches_view_edge
from pipeline.perception.support import recentre
from pipeline.registry import StageRegistry
from pipeline.types import (
    AfterView,
    Contacts,
    DepthObservation,
    EstimateResult,
    GraspPlan,
    PointCloud,
    SymmetryInit,
)

#: The grasps' after-views of an object, given its cloud (one per grasp, None: none).
AfterViews = Callable[[PointCloud], tuple[AfterView | None, ...]]

#: Pixels between an object and the edge of the view below which it is set aside.
VIEW_EDGE_MARGIN_PX = 2
#: What ``--object`` accepts besides an object number.
OBJECT_CHOICES = ("all", "largest", "nearest")
#: Why a cluster at the edge of the view is set aside, as the table and scene.png say it.
SET_ASIDE_REASON = "at the edge of the view"


@dataclass(frozen=True)
class ObjectCompletion:
    """One segmented object and what became of it.

    Attributes:
        index: its number (0 = the largest object).
        cloud: its points, frame R, with their pixels.
        status: ``"not selected"``, ``"asymmetric"`` (without contacts: the initialiser
            found no mirror plane the view supports; the visible cloud is the object, with
            no mirrored half), ``"rejected"`` (the same with contacts to fuse),
            ``"completed"`` (Stage 0 without contacts), or the fused estimate's status.
        init: the initialiser's output, when it ran.
        result: Stage 0 (and 1, 2 when fused), when there is one.
        reason: why it was rejected, else empty.
        flags: what the capture says against a completion it did not refute (see
            :func:`support_flags`), else empty.
    """

    index: int
    cloud: PointCloud
    status: str
    init: SymmetryInit | None = None
    result: EstimateResult | None = None
    reason: str = ""
    flags: tuple[str, ...] = ()


@dataclass(frozen=True)
class SceneCompletion:
    """Everything ``symfuse complete`` found and computed in one view.

    Attributes:
        observation: the view, with ``T_robot_camera`` in the frame the objects are in.
        objects: every object, largest first.
        set_aside: the clusters that touch the edge of the view (frame R, with pixels).
    """

    observation: DepthObservation
    objects: tuple[ObjectCompletion, ...]
    set_aside: tuple[PointCloud, ...]


def segment_scene(
    segmenter, observation: DepthObservation
) -> tuple[DepthObservation, list[PointCloud], list[PointCloud]]:
    """The objects in view (largest first), the clusters set aside at the edge of the view,
    and the observation, its frame recentred below the largest object when the
    frame was built on the support plane.

    Raises:
        StageFailure: no object, or every object touches the edge of the view.
    """
    outside = outside_view(np.isfinite(observation.depth_m))
    objects, set_aside = [], []
    for cloud in segmenter.segment_objects(observation):
        if touches_view_edge(cloud.pixels, outside, VIEW_EDGE_MARGIN_PX):
            set_aside.append(cloud)
        else:
            objects.append(cloud)
    if not objects:
        raise StageFailure(
            f"segmenter '{segmenter.name}': every object ({len(set_aside)}) touches the "
            "edge of the view"
        )
    if observation.frame_from_support:
        centroid = objects[0].points.mean(axis=0)
        observation = dataclasses.replace(
            observation, T_robot_camera=recentre(observation.T_robot_camera, centroid)
        )
        shift = np.array([centroid[0], centroid[1], 0.0])
        objects = [dataclasses.replace(c, points=c.points - shift) for c in objects]
        set_aside = [dataclasses.replace(c, points=c.points - shift) for c in set_aside]
    return observation, objects, set_aside


def select_objects(
    which: str, objects: Sequence[PointCloud], observation: DepthObservation, fusing: bool
) -> list[int]:
    """Indices of the objects ``--object`` names: ``all``, ``largest`` (0), ``nearest``
    (to the camera) or a number. Fusion with contacts takes one object.

    Raises:
        ConfigError: an unknown choice or number, or ``all`` with contacts.
    """
    if which == "all":
        if fusing and len(objects) > 1:
            raise ConfigError(
                f"--object all: contacts belong to one object, and {len(objects)} were "
                "found; choose --object largest, nearest or a number"
            )
        return list(range(len(objects)))
    if which == "largest":
        return [0]
    if which == "nearest":
        camera = np.asarray(observation.T_robot_camera)[:3, 3]
        distances = [np.linalg.norm(c.points.mean(axis=0) - camera) for c in objects]
        return [int(np.argmin(distances))]
    if not (which.isascii() and which.isdigit()):
        raise ConfigError(f"--object {which}: expected {', '.join(OBJECT_CHOICES)} or a number")
    if int(which) >= len(objects):
        raise ConfigError(f"--object {which}: only {len(objects)} objects were found (0-based)")
    return [int(which)]


def complete_object(
    config: Config,
    registry: StageRegistry,
    index: int,
    cloud: PointCloud,
    observation: DepthObservation,
    grasps: Sequence[Contacts],
    plans: Sequence[GraspPlan | None],
    after_views: AfterViews | None = None,
) -> ObjectCompletion:
    """Initialise one object's plane and complete it (Stage 0), fusing ``grasps`` when
    there are any (Stages 1, 2), with the grasps' after-views ``after_views`` finds for the
    object's cloud (docs/after-view.md)."""
    from pipeline.run.runner import (  # the estimator's scipy: only when used
        estimate,
        initial_estimate,
    )

    initialiser = config.create(registry, "initialiser")
    proposal = initialiser.propose(cloud, observation)
    init = proposal
    if grasps:
        init = initialiser.refine(proposal, cloud, plans[0] if plans else None, grasps[0])
    if init.status != "ok" and not grasps:
        # No mirror plane the view supports: the object is what was seen of it.
        return ObjectCompletion(index, cloud, "asymmetric", init, reason=init.reason)
    if init.status != "ok":
        return ObjectCompletion(index, cloud, "rejected", init, reason=init.reason)
    if not grasps:
        result = initial_estimate(cloud, init)
        return ObjectCompletion(
            index, cloud, "completed", init, result, flags=support_flags(cloud, init)
        )
    # With the depth image, as in a trial: the camera's free space catches contacts of
    # another scene, which the taxels alone explain by any plane they pull the model to.
    views = after_views(cloud) if after_views is not None else ()
    result = estimate(config, registry, cloud, init, grasps, observation, views)
    return ObjectCompletion(index, cloud, result.final.status, init, result)


def support_flags(cloud: PointCloud, init: SymmetryInit) -> tuple[str, ...]:
    """A flag when the mirror plane has no evidence in the view: fewer than
    :data:`~pipeline.symmetry.support.MIN_MIRROR_SUPPORT` of the visible points meet their
    own mirror image (:func:`~pipeline.symmetry.support.mirror_support`), so the mirrored
    half is nowhere checked against the data (a laptop's lid mirrored into a tent), and
    the view is no body of revolution whose axis the plane contains
    (:func:`~pipeline.symmetry.support.axis_supports`). An axis carries its own evidence
    (its slices are circles) and is not flagged."""
    from pipeline.symmetry.support import (
        COUNTERPART_M,
        MIN_MIRROR_SUPPORT,
        axis_supports,
        mirror_support,
    )

    if not init.proposed.is_plane:
        return ()
    support = mirror_support(cloud.points, init.proposed)
    if support >= MIN_MIRROR_SUPPORT or axis_supports(cloud.points, init.proposed):
        return ()
    return (
        f"unsupported mirror plane: {support:.0%} of the visible points meet their mirror "
        f"image within {COUNTERPART_M * 1e3:.0f} mm (< {MIN_MIRROR_SUPPORT:.0%}); the "
        "mirrored half lies where the camera could not check it",
    )


def complete_scene(
    config: Config,
    registry: StageRegistry,
    which: str,
    grasps: Sequence[Contacts] = (),
    plans: Sequence[GraspPlan | None] = (),
    after_views: AfterViews | None = None,
) -> SceneCompletion:
    """Observe with the configured sensor, segment every object, complete the ones
    ``which`` selects (see :func:`select_objects`), fusing ``grasps`` when given (with
    their after-views, ``after_views`` of the object's cloud)."""
    observation = config.create(registry, "sensor").observe(None)
    segmenter = config.create(registry, "segmenter")
    observation, clouds, set_aside = segment_scene(segmenter, observation)
    selected = set(select_objects(which, clouds, observation, bool(grasps)))
    objects = tuple(
        complete_object(config, registry, index, cloud, observation, grasps, plans, after_views)
        if index in selected
        else ObjectCompletion(index, cloud, "not selected")
        for index, cloud in enumerate(clouds)
    )
    return SceneCompletion(observation, objects, tuple(set_aside))


def footprint_extents(points: np.ndarray) -> list[float]:
    """Extents (m) of points' footprint along its PCA major and minor axes."""
    axes = table_axes(points)
    return [float(np.ptp(points @ axis)) for axis in (axes.major, axes.minor)]


def object_summary(completion: ObjectCompletion) -> dict[str, Any]:
    """One entry of ``objects.json``: number, size, where, and its plane and status."""
    from pipeline.io.formats import plane_to_json

    points = completion.cloud.points
    entry: dict[str, Any] = {
        "index": completion.index,
        "points": len(points),
        "centroid": points.mean(axis=0).tolist(),
        "footprint_extents_m": footprint_extents(points),
        "height_m": float(points[:, 2].max()),
        "pixels": pixel_box(completion.cloud.pixels),
        "status": completion.status,
    }
    if completion.result is not None:
        final = completion.result.final
        entry["plane"] = plane_to_json(final.plane)
        entry["completed_extents_m"] = plane_extents(final.completed, final.plane.normal)
    if completion.reason:
        entry["reason"] = completion.reason
    if completion.flags:
        entry["flags"] = list(completion.flags)
    return entry


def pixel_box(pixels: np.ndarray) -> dict[str, list[int]]:
    """The first and last image row and column of ``(N, 2)`` pixels (rows, cols)."""
    rows, cols = pixels[:, 0], pixels[:, 1]
    return {"rows": [int(rows.min()), int(rows.max())], "cols": [int(cols.min()), int(cols.max())]}


def plane_extents(points: np.ndarray, normal: np.ndarray) -> dict[str, float]:
    """Extents (m) of points across the symmetry plane (along its normal) and along it."""
    along = np.array([-normal[1], normal[0], 0.0])
    return {
        "across_plane": float(np.ptp(points @ normal)),
        "along_plane": float(np.ptp(points @ along)),
    }


def failed(completions: Sequence[ObjectCompletion], failed_statuses: Sequence[str]) -> list[str]:
    """One line per selected object whose initialisation or estimate failed."""
    return [
        f"object {c.index}: {c.status}" + (f" ({c.reason})" if c.reason else "")
        for c in completions
        if c.status == "rejected" or c.status in failed_statuses
    ]
