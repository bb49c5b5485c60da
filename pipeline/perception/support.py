"""A robot frame for a capture that has none: the support plane (table or floor) and a frame
standing on it.

The frame built here, ``R``, has z along the plane's normal pointing toward the camera
(up), its origin on the plane (at the foot of the camera until :func:`recentre` moves it
below an object) and x along the camera's optical axis projected onto the plane, so a
robot-frame picture seen from above shows the scene as the camera looked at it, from
the bottom of the picture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.perception.table import refit_until_settled


@dataclass(frozen=True)
class SupportPlane:
    """The plane ``{p : normal . p = offset_m}`` in the camera frame, ``normal`` a unit
    vector pointing to the camera's side; ``inliers`` is how many points lie on it."""

    normal: np.ndarray
    offset_m: float
    inliers: int


#: Cosine of the largest angle between a support's normal and the image's up axis (-y)
#: for it to count as facing up: a table or floor seen by a camera that looks down at it.
MIN_UP_COSINE = float(np.cos(np.deg2rad(70.0)))
#: Least number of voxels of surface standing above a plane for it to support anything.
MIN_VOXELS_ABOVE = 20
#: Points the final least-squares refit sees (a seeded subsample: the fit is the same
#: from run to run, and does not cost more on a larger image).
REFIT_SAMPLE = 20000


def candidate_planes(
    cloud_points: np.ndarray,
    *,
    inlier_distance_m: float,
    iterations: int,
    max_planes: int,
    min_points: int,
    seed: int,
) -> list[tuple[np.ndarray, float]]:
    """The dominant planes of a cloud, one after the other (open3d RANSAC on what the
    planes before left), each refitted to its inliers; normals toward the camera at the
    origin. Stops after ``max_planes`` or when a plane holds fewer than ``min_points``."""
    from pipeline.io.open3d_loader import open3d

    o3d = open3d()
    o3d.utility.random.seed(seed)
    rest = np.asarray(cloud_points, dtype=np.float64)
    planes = []
    for _ in range(max_planes):
        if len(rest) < max(3, min_points):
            break
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rest))
        model, on_plane = cloud.segment_plane(
            distance_threshold=inlier_distance_m, ransac_n=3, num_iterations=iterations
        )
        if len(on_plane) < max(3, min_points):
            break
        scale = float(np.linalg.norm(model[:3]))
        normal, offset = np.asarray(model[:3]) / scale, -float(model[3]) / scale
        normal, offset, _ = refit_until_settled(rest, normal, offset, inlier_distance_m)
        if offset > 0.0:  # camera at the origin: its height above the plane is -offset
            normal, offset = -normal, -offset
        planes.append((normal, offset))
        rest = np.delete(rest, np.asarray(on_plane, dtype=np.int64), axis=0)
    return planes


def fit_support_plane(
    points_camera: np.ndarray,
    *,
    inlier_distance_m: float = 0.01,
    iterations: int = 1000,
    voxel_m: float = 0.01,
    seed: int = 0,
    max_planes: int = 4,
    min_fraction: float = 0.1,
) -> SupportPlane:
    """The plane the scene stands on, in the camera frame, its normal toward the camera.

    The candidates are the scene's dominant planes (:func:`candidate_planes`, on a
    ``voxel_m`` grid so that near and far surfaces weigh by area rather than by how many
    pixels they fill), each holding at least ``min_fraction`` of the voxels. A support
    has the camera above it and at least :data:`MIN_VOXELS_ABOVE` voxels of surface
    standing on it (more than two inlier distances above, less than a metre): a carton's
    face has the rest of the carton behind it, not in front. Among the supports, those
    facing up in the image (normal within 70 deg of the image's -y axis: the camera looks
    down at a table, and sees a wall behind it face on) come first, then the one holding
    most voxels. The winner is refitted by least squares to its inliers among a seeded
    subsample of :data:`REFIT_SAMPLE` points, and its inliers are counted on every point.

    Raises:
        ValueError: fewer than 3 points, or no plane is a support (named why).
    """
    points = np.asarray(points_camera, dtype=np.float64)
    if len(points) < 3:
        raise ValueError(f"a plane needs at least 3 points, got {len(points)}")
    grid = points
    if voxel_m > 0.0:
        from pipeline.io.open3d_loader import open3d

        o3d = open3d()
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        grid = np.asarray(cloud.voxel_down_sample(voxel_m).points)
    if len(grid) < 3:
        raise ValueError("fewer than 3 points are left on the voxel grid")
    planes = candidate_planes(
        grid,
        inlier_distance_m=inlier_distance_m,
        iterations=iterations,
        max_planes=max_planes,
        min_points=int(np.ceil(min_fraction * len(grid))),
        seed=seed,
    )
    if not planes:
        raise ValueError(f"no plane holds {min_fraction:.0%} of the scene")
    ranked, refused = [], []
    for normal, offset in planes:
        height = grid @ normal - offset
        held = int(np.sum(np.abs(height) < inlier_distance_m))
        above = int(np.sum((height > 2.0 * inlier_distance_m) & (height < 1.0)))
        if -offset < inlier_distance_m:
            refused.append("one passes through the camera")
        elif above < MIN_VOXELS_ABOVE:
            refused.append(f"one has nothing standing on it ({above} voxels above)")
        else:
            ranked.append((-normal[1] >= MIN_UP_COSINE, held, normal, offset))
    if not ranked:
        raise ValueError(
            f"none of the {len(planes)} dominant planes is a support: {'; '.join(refused)}"
        )
    _, _, normal, offset = max(ranked, key=lambda entry: entry[:2])
    rng = np.random.default_rng(seed)
    sample = points[rng.choice(len(points), size=min(REFIT_SAMPLE, len(points)), replace=False)]
    normal, offset, _ = refit_until_settled(sample, normal, offset, inlier_distance_m)
    if offset > 0.0:
        normal, offset = -normal, -offset
    inliers = np.abs(points @ normal - offset) < inlier_distance_m
    return SupportPlane(normal=normal, offset_m=offset, inliers=int(inliers.sum()))


def frame_on_plane(plane: SupportPlane) -> np.ndarray:
    """``T_robot_camera`` of the frame standing on ``plane`` (see the module docstring).

    When the camera looks straight down, the image's downward axis (+y) projected on the
    plane is used as x instead of the optical axis.
    """
    up = plane.normal
    for axis in (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])):
        forward = axis - (axis @ up) * up
        if np.linalg.norm(forward) > 1e-3:
            break
    x_axis = forward / np.linalg.norm(forward)
    y_axis = np.cross(up, x_axis)
    T_camera_robot = np.eye(4)
    T_camera_robot[:3, :3] = np.column_stack([x_axis, y_axis, up])
    T_camera_robot[:3, 3] = plane.offset_m * up  # the camera's foot on the plane
    return np.linalg.inv(T_camera_robot)


def recentre(T_robot_camera: np.ndarray, point_robot: np.ndarray) -> np.ndarray:
    """The same frame moved along its x-y plane so that its origin lies below
    ``point_robot``: ``T_new_old @ T_robot_camera`` with ``T_new_old`` a translation by
    ``(-x, -y, 0)``."""
    shift = np.eye(4)
    shift[:2, 3] = -np.asarray(point_robot, dtype=np.float64)[:2]
    return shift @ np.asarray(T_robot_camera, dtype=np.float64)
