"""PyBullet camera rendering: metric depth, pixel geometry and camera poses."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from pipeline.geometry.poses import look_at as look_at_rad
from pipeline.sim.camera import calibration_error, render
from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT
from pipeline.sim.scene import Scene
from pipeline.types import CameraIntrinsics


def look_at(target_m, distance_m, elevation_deg, azimuth_deg):
    """:func:`pipeline.geometry.poses.look_at` with the angles in degrees, as the sensors take
    them."""
    return look_at_rad(target_m, distance_m, np.deg2rad(elevation_deg), np.deg2rad(azimuth_deg))


def back_project(depth_m, intrinsics, T_robot_camera, rows, cols):
    """Independent pinhole back-projection of selected pixels into frame R."""
    z = depth_m[rows, cols].astype(np.float64)
    points_camera = np.stack(
        [(cols - intrinsics.cx) * z / intrinsics.fx, (rows - intrinsics.cy) * z / intrinsics.fy, z],
        axis=1,
    )
    return points_camera @ T_robot_camera[:3, :3].T + T_robot_camera[:3, 3]


def standing_box(size_m):
    box = trimesh.creation.box(size_m)
    box.apply_translation((0.0, 0.0, size_m[2] / 2))
    return box


@pytest.mark.parametrize("elevation_deg", [0.0, 45.0, 90.0])
@pytest.mark.parametrize("azimuth_deg", [0.0, 135.0, 180.0])
def test_look_at_pose(elevation_deg, azimuth_deg):
    target = np.array([0.4, -0.1, 0.05])
    T = look_at(target, 0.9, elevation_deg, azimuth_deg)
    rotation, position = T[:3, :3], T[:3, 3]
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)
    assert np.linalg.norm(position - target) == pytest.approx(0.9)
    # The optical axis (camera z) points at the target; the image x axis is horizontal.
    np.testing.assert_allclose(rotation[:, 2], (target - position) / 0.9, atol=1e-12)
    assert rotation[2, 0] == pytest.approx(0.0, abs=1e-12)
    assert position[2] - target[2] == pytest.approx(0.9 * np.sin(np.deg2rad(elevation_deg)))
    # Image y (down) never points up.
    assert rotation[2, 1] <= 1e-12


def test_frontal_box_face_renders_at_metric_depth_and_back_projects():
    # Camera at elevation 0 looking along +x at a box face 0.95 m away.
    size = (0.1, 0.2, 0.2)
    with Scene() as scene:
        box_id = scene.add_object(standing_box(size), 0.5, 0.5, x_m=0.5)
        T_robot_camera = look_at(np.array([0.5, 0.0, 0.1]), 1.0, 0.0, 180.0)
        rendering = render(scene.client, KINECT, T_robot_camera)
    mask = ndimage.binary_erosion(rendering.segmentation == box_id, iterations=2)
    rows, cols = np.nonzero(mask)
    assert len(rows) > 5000
    np.testing.assert_allclose(rendering.depth_m[rows, cols], 0.95, atol=1e-3)
    points = back_project(rendering.depth_m, KINECT, T_robot_camera, rows, cols)
    np.testing.assert_allclose(points[:, 0], 0.45, atol=1e-3)
    assert points[:, 1].min() > -0.1 - 1e-3 and points[:, 1].max() < 0.1 + 1e-3
    assert points[:, 2].min() > -1e-3 and points[:, 2].max() < 0.2 + 1e-3
    # The silhouette holds exactly the pixels whose centres see the face (pinhole model).
    full = np.nonzero(rendering.segmentation == box_id)
    z = 0.95
    edge_cols = np.array([-0.1, 0.1]) * KINECT.fx / z + KINECT.cx  # camera x = -y_R
    edge_rows = np.array([-0.1, 0.1]) * KINECT.fy / z + KINECT.cy  # camera y = 0.1 - z_R
    assert full[1].min() == np.ceil(edge_cols[0]) and full[1].max() == np.floor(edge_cols[1])
    assert full[0].min() == np.ceil(edge_rows[0]) and full[0].max() == np.floor(edge_rows[1])


@pytest.mark.parametrize(
    "intrinsics",
    [KINECT, CameraIntrinsics(400, 300, 420.0, 455.0, 180.2, 160.7)],
    ids=["kinect", "off-centre"],
)
def test_depth_of_tilted_rolled_view_matches_ray_plane_intersection(intrinsics):
    T_robot_camera = look_at(np.zeros(3), 1.0, 30.0, 20.0)
    roll = np.array([[np.cos(0.5), -np.sin(0.5), 0], [np.sin(0.5), np.cos(0.5), 0], [0, 0, 1]])
    T_robot_camera[:3, :3] = T_robot_camera[:3, :3] @ roll
    with Scene() as scene:
        rendering = render(scene.client, intrinsics, T_robot_camera)
        table = rendering.segmentation == scene.table_id
    rows, cols = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width]
    rays_camera = np.stack(
        [(cols - intrinsics.cx) / intrinsics.fx, (rows - intrinsics.cy) / intrinsics.fy],
        axis=-1,
    )
    rays_camera = np.concatenate([rays_camera, np.ones((*rows.shape, 1))], axis=-1)
    rays_robot_z = rays_camera @ T_robot_camera[2, :3]
    depth_on_table = -T_robot_camera[2, 3] / rays_robot_z  # table top z = 0
    assert table.mean() > 0.5
    np.testing.assert_allclose(rendering.depth_m[table], depth_on_table[table], atol=5e-5)


def test_oblique_view_back_projects_onto_table_and_box_top():
    table_height_m = 0.1
    size = (0.12, 0.12, 0.15)
    with Scene(table_height_m=table_height_m) as scene:
        box_id = scene.add_object(standing_box(size), 0.5, 0.5, x_m=0.6, y_m=0.05, yaw_rad=0.3)
        T_robot_camera = look_at(np.array([0.6, 0.05, 0.15]), 0.8, 45.0, 160.0)
        rendering = render(scene.client, KINECT, T_robot_camera)
        table = ndimage.binary_erosion(rendering.segmentation == scene.table_id, iterations=2)
    rows, cols = np.nonzero(table)
    table_points = back_project(rendering.depth_m, KINECT, T_robot_camera, rows, cols)
    np.testing.assert_allclose(table_points[:, 2], table_height_m, atol=1e-3)
    # Box top face: box pixels above the top's interior back-project to z = table + 0.15.
    box = ndimage.binary_erosion(rendering.segmentation == box_id, iterations=2)
    rows, cols = np.nonzero(box)
    box_points = back_project(rendering.depth_m, KINECT, T_robot_camera, rows, cols)
    c, s = np.cos(0.3), np.sin(0.3)
    in_box_frame = (box_points[:, :2] - [0.6, 0.05]) @ np.array([[c, -s], [s, c]])
    inside_top = np.all(np.abs(in_box_frame) < 0.055, axis=1) & (
        box_points[:, 2] > table_height_m + 0.1
    )
    assert inside_top.sum() > 500
    np.testing.assert_allclose(box_points[inside_top, 2], table_height_m + 0.15, atol=1e-3)


def test_background_is_nan_and_colour_is_rgb():
    with Scene() as scene:
        # Looking horizontally over the table edge: the upper half sees nothing.
        rendering = render(scene.client, KINECT, look_at(np.zeros(3), 1.0, 0.0, 0.0))
    assert rendering.rgb.shape == (480, 640, 3) and rendering.rgb.dtype == np.uint8
    assert np.isnan(rendering.depth_m[:200]).all()
    assert (rendering.segmentation[:200] == -1).all()


def test_calibration_error_is_planar_motion_about_pivot():
    T_true = look_at(np.array([0.5, 0.0, 0.05]), 1.0, 45.0, 180.0)
    pivot = np.array([0.5, 0.0, 0.05])
    yaw = np.deg2rad(3.0)
    translation = np.array([0.01, -0.02, 0.0])
    T_believed = calibration_error(T_true, yaw, translation, pivot)
    points_robot = np.array([[0.5, 0.0, 0.05], [0.6, 0.1, 0.2], [0.4, -0.05, 0.0]])
    points_camera = (points_robot - T_true[:3, 3]) @ T_true[:3, :3]
    believed = points_camera @ T_believed[:3, :3].T + T_believed[:3, 3]
    c, s = np.cos(yaw), np.sin(yaw)
    expected = (points_robot - pivot) @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) + pivot
    np.testing.assert_allclose(believed, expected + translation, atol=1e-12)
