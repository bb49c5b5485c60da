"""The object's visible points in the after-view: the camera's second look while the hand
holds the object (docs/after-view.md).

The first view's segmentation does not carry over: the hand now stands over the object and
touches it, so one cluster would hold both. The object is instead what the after-view sees
near where the first view saw it (the grasp moves it by millimetres), above the table, less
what the hand covers. The hand is masked by its *known* pose (the arm's kinematics and the
finger joints, as a robot knows them), not by the simulator's labels: every point within
``hand_margin_m`` of the hand's surface is dropped. The margin covers the depth noise and
the camera's calibration error, which displaces the hand in the camera's frame as it does
the object; object points that near the hand are lost, which only costs the registration
points.

The geometry is pure (the hand's surface comes in as sampled points, :func:`hand_surface`);
:func:`look_after` asks the sensor and the world for the view and the hand through their
stage contracts.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from pipeline.perception.depth import backproject_depth
from pipeline.stages import SensorSource, World
from pipeline.types import AfterView, DepthObservation, GraspOutcome, GraspPlan, PointCloud


@dataclass(frozen=True)
class AfterViewCrop:
    """Which after-view points are the object's.

    Attributes:
        reach_m: the farthest a point may lie (horizontally, and above the first view's
            top) from the first view's object points (m): the largest motion expected of
            the object in a grasp, three stds of the bias prior's.
        table_clearance_m: points lower than this above the table are the table's (m).
        hand_margin_m: points nearer than this to the hand's surface are the hand's (m):
            three stds of the depth noise plus the calibration error's displacement.
        hand_spacing_m: the hand's surface is sampled at about this spacing (m).
    """

    reach_m: float = 0.03
    table_clearance_m: float = 0.005
    hand_margin_m: float = 0.015
    hand_spacing_m: float = 0.002


def hand_surface(
    meshes: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]], spacing_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """``(K, 3)`` points on every triangle of the hand's link meshes (``link -> (vertices,
    faces, normals)``, frame R), no two neighbours farther apart than about ``spacing_m``
    (each triangle gets a barycentric grid fine enough for its longest edge), and each
    point's ``(K, 3)`` unit normal, its triangle's."""
    samples, normals = [], []
    for vertices, faces, vertex_normals in meshes.values():
        corners = np.asarray(faces, dtype=np.int64)
        triangles = np.asarray(vertices, dtype=float)[corners]
        # The triangle's own normal, turned outward as its vertex normals say.
        facing = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        facing /= np.maximum(np.linalg.norm(facing, axis=1, keepdims=True), 1e-300)
        outward = np.asarray(vertex_normals, dtype=float)[corners].sum(axis=1)
        facing *= np.where(np.einsum("ij,ij->i", facing, outward) < 0.0, -1.0, 1.0)[:, None]
        edges = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max(axis=1)
        divisions = np.maximum(np.ceil(edges / spacing_m), 1).astype(int)
        for steps in np.unique(divisions):
            grid = [(i, j) for i in range(steps + 1) for j in range(steps + 1 - i)]
            weights = np.array(grid, dtype=float) / steps
            barycentric = np.column_stack([weights, 1.0 - weights.sum(axis=1)])
            chosen = divisions == steps
            grid_points = np.einsum("kb,tbj->tkj", barycentric, triangles[chosen])
            samples.append(grid_points.reshape(-1, 3))
            normals.append(np.repeat(facing[chosen], len(grid), axis=0))
    if not samples:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.vstack(samples), np.vstack(normals)


def outside_hand(points: np.ndarray, hand_points: np.ndarray, margin_m: float) -> np.ndarray:
    """``(N,)`` bool: the points farther than ``margin_m`` from every hand surface point."""
    if len(hand_points) == 0 or len(points) == 0:
        return np.ones(len(points), dtype=bool)
    distance, _ = cKDTree(hand_points).query(points, distance_upper_bound=margin_m)
    return ~np.isfinite(distance)


def split_points(
    points: np.ndarray,
    first_points: np.ndarray,
    table_height_m: float,
    hand_points: np.ndarray,
    crop: AfterViewCrop,
) -> tuple[np.ndarray, np.ndarray]:
    """The after-view's ``points`` (frame R) that belong to the object, and those on the
    hand. The object's lie within ``crop.reach_m`` of the first view's ``first_points``
    horizontally and no higher than that above their top, above the table and outside the
    hand's margin; the hand's are the points above the table inside that margin."""
    above = points[:, 2] > table_height_m + crop.table_clearance_m
    clear = np.ones(len(points), dtype=bool)
    clear[above] = outside_hand(points[above], hand_points, crop.hand_margin_m)
    below = points[:, 2] < first_points[:, 2].max() + crop.reach_m
    near = np.zeros(len(points), dtype=bool)
    candidates = np.flatnonzero(above & below & clear)
    if candidates.size:
        distance, _ = cKDTree(first_points[:, :2]).query(
            points[candidates, :2], distance_upper_bound=crop.reach_m
        )
        near[candidates[np.isfinite(distance)]] = True
    return points[near], points[above & ~clear]


def after_view(
    observation: DepthObservation,
    first_points: np.ndarray,
    table_height_m: float,
    hand: tuple[np.ndarray, np.ndarray],
    crop: AfterViewCrop,
) -> AfterView:
    """The :class:`AfterView` of ``observation``: its object and hand points by
    :func:`split_points`, with ``hand``, the hand's surface points and their normals
    where its known pose puts it (:func:`hand_surface`)."""
    points, _ = backproject_depth(
        observation.depth_m, observation.intrinsics, observation.T_robot_camera
    )
    surface, normals = hand
    visible, seen = split_points(points, first_points, table_height_m, surface, crop)
    return AfterView(
        observation, visible, hand_points=seen, hand_surface=surface, hand_normals=normals
    )


def look_after(
    sensor: SensorSource,
    world: World,
    first: DepthObservation,
    cloud: PointCloud,
    outcome: GraspOutcome,
    plan: GraspPlan,
    crop: AfterViewCrop = AfterViewCrop(),
) -> AfterView | None:
    """The after-view of a grasp the hand still holds: ``sensor`` looks at ``world`` again
    from ``first``'s camera, and the hand is masked where the grasp's ``outcome`` (its palm
    pose and finger joints) puts it. None when the sensor cannot look again."""
    observation = sensor.observe_again(world, first)
    if observation is None:
        return None
    meshes = world.hand_meshes(
        plan.gripper, outcome.joint_positions, np.asarray(outcome.T_robot_hand), plan
    )
    hand, hand_normals = hand_surface(meshes, crop.hand_spacing_m)
    table_height_m = first.table_height_m
    if table_height_m is None:
        table_height_m = float(np.min(cloud.points[:, 2]))
    return after_view(observation, cloud.points, table_height_m, (hand, hand_normals), crop)
