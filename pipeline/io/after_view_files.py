"""The after-view on disk (docs/after-view.md): ``after_depth.npy`` (grasp 1) and
``after_depth_K.npy`` (grasp K > 1) beside ``contacts.json``, whose grasp entry names its
file (``"after_depth"``) and holds the hand's pose while it held the object (``"hand"``:
``T_robot_hand`` and ``joint_positions``), which masks the hand out of the view.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import InputError
from pipeline.io.formats import RecordedGrasps
from pipeline.stages import World
from pipeline.types import AfterView, GraspOutcome, PointCloud


def after_depth_name(k: int) -> str:
    """The file of grasp ``k``'s (from 0) after-view depth image."""
    return "after_depth.npy" if k == 0 else f"after_depth_{k + 1}.npy"


def hand_to_json(outcome: GraspOutcome) -> dict[str, Any]:
    """The hand's palm pose and finger joints while it held the object."""
    return {
        "T_robot_hand": np.asarray(outcome.T_robot_hand).tolist(),
        "joint_positions": {name: float(v) for name, v in outcome.joint_positions.items()},
    }


def write_after_view(
    out_dir: Path, k: int, view: AfterView | None, outcome: GraspOutcome
) -> dict[str, Any]:
    """Write grasp ``k``'s after-view depth image (metres, NaN = no return) into
    ``out_dir``; return its ``contacts.json`` entries (none without a view)."""
    if view is None:
        return {}
    name = after_depth_name(k)
    np.save(out_dir / name, view.observation.depth_m)
    return {"after_depth": name, "hand": hand_to_json(outcome)}


def read_after_views(
    recorded: RecordedGrasps,
    cloud: PointCloud,
    world: type[World],
    first_depth: tuple[Path | None, Path | None] = (None, None),
) -> tuple[AfterView | None, ...]:
    """Each recorded grasp's after-view, None where it has none: the depth image its
    ``"after_depth"`` names (``first_depth``, ``(--after-depth, --after-camera)``, replaces
    grasp 1's) with the ``camera.json`` beside it, the object's points in it by the first
    view's ``cloud``, the hand masked where its recorded pose puts it (drawn by ``world``,
    the configured world's class, which knows the hands).

    Raises:
        InputError: an unreadable image, a camera without a pose in the robot frame, or a
            grasp with an after-view but no recorded plan or hand pose.
    """
    from pipeline.io.captures import depth_camera_path, read_depth_image
    from pipeline.perception.after_view import AfterViewCrop, after_view, hand_surface

    crop = AfterViewCrop()
    depths = list(recorded.after_depth) or [None] * len(recorded.contacts)
    cameras: list[Path | None] = [None] * len(depths)
    if first_depth[0] is not None:
        depths[0], cameras[0] = first_depth
    views: list[AfterView | None] = []
    for k, (depth, camera) in enumerate(zip(depths, cameras, strict=True)):
        if depth is None:
            views.append(None)
            continue
        plan = recorded.plans[k] if k < len(recorded.plans) else None
        hand = recorded.hands[k] if k < len(recorded.hands) else None
        if plan is None or hand is None:
            raise InputError(
                f"{depth}: grasp {k + 1}'s after-view needs the grasp's 'plan' and 'hand' in "
                "the contacts file, to mask the hand out of it"
            )
        capture = read_depth_image(depth, camera, None)
        if capture.T_robot_camera is None:
            raise InputError(
                f"{depth_camera_path(depth, camera)}: no T_robot_camera: the after-view's "
                "camera must be placed in the robot frame, as the cloud is"
            )
        observation = capture.view(capture.T_robot_camera, capture.table_height_m)
        meshes = world.hand_meshes(plan.gripper, hand.joint_positions, hand.T_robot_hand, plan)
        table_m = capture.table_height_m
        if table_m is None:
            table_m = float(np.min(cloud.points[:, 2]))
        surface = hand_surface(meshes, crop.hand_spacing_m)
        views.append(after_view(observation, cloud.points, table_m, surface, crop))
    return tuple(views)
