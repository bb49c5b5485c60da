"""Depth back-projection, table RANSAC, clustering and the two segmenters."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.errors import EXIT_BAD_INPUT, PluginError, StageFailure
from pipeline.geometry.poses import look_at
from pipeline.io.open3d_loader import open3d
from pipeline.perception.clustering import (
    dbscan_labels,
    largest_cluster_indices,
    voxel_subsample_indices,
)
from pipeline.perception.depth import backproject_depth, project_points
from pipeline.perception.segmentation import merge_overlapping_footprints, segment_points
from pipeline.perception.table import fit_table_ransac, table_from_height
from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT
from pipeline.synthetic import box_object, render_depth, synthetic_observation
from pipeline.types import CameraIntrinsics, DepthObservation, PointCloud
from plugins.segmenters.ground_truth_mask import GroundTruthMask
from plugins.segmenters.table_cluster import TableCluster

SMALL = CameraIntrinsics(width=8, height=6, fx=10.0, fy=12.0, cx=3.5, cy=2.5)


def test_backprojection_matches_pinhole_by_hand():
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T[:3, 3] = [1.0, 2.0, 3.0]
    depth = np.full((6, 8), np.nan, dtype=np.float32)
    depth[4, 1] = 2.0
    points, pixels = backproject_depth(depth, SMALL, T)
    # Pixel (row 4, col 1): x_c = (1 - 3.5) * 2 / 10 = -0.5, y_c = (4 - 2.5) * 2 / 12 = 0.25.
    expected = T[:3, :3] @ np.array([-0.5, 0.25, 2.0]) + T[:3, 3]
    np.testing.assert_allclose(points, [expected])
    np.testing.assert_array_equal(pixels, [[4, 1]])
    rows, cols, z = project_points(points, SMALL, T)
    assert (rows[0], cols[0]) == (4, 1)
    assert z[0] == pytest.approx(2.0)


def test_renderer_depth_of_a_box_top_seen_from_straight_above():
    # Camera 1 m above the table looking straight down: the table is at depth 1 m, the top
    # of a 0.1 m tall box at 0.9 m.
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [0.0, 0.0, 1.0]
    depth, mask = render_depth(box_object(0.1, 0.1, 0.1), (0.0, 0.0, 0.3), 0.0, KINECT, T)
    assert depth[240, 315] == pytest.approx(0.9, abs=1e-6)
    assert depth[10, 10] == pytest.approx(1.0, abs=1e-6)
    assert mask[240, 315] and not mask[10, 10]


def test_ransac_finds_a_known_tilted_table():
    rng = np.random.default_rng(3)
    normal = np.array([0.05, -0.03, 1.0])
    normal /= np.linalg.norm(normal)
    xy = rng.uniform(-0.5, 0.5, size=(20000, 2))
    z = (0.73 - normal[0] * xy[:, 0] - normal[1] * xy[:, 1]) / normal[2]
    table = np.column_stack([xy, z + rng.normal(0, 0.001, len(xy))])
    clutter = rng.uniform([-0.5, -0.5, 0.75], [0.5, 0.5, 1.2], size=(8000, 3))
    wall = np.column_stack(  # a vertical plane must not win: it is not near horizontal
        [np.full(15000, 0.6), rng.uniform(-0.5, 0.5, 15000), rng.uniform(0.0, 1.5, 15000)]
    )
    plane, inliers = fit_table_ransac(np.concatenate([table, clutter, wall]), rng)
    assert np.degrees(np.arccos(plane.normal @ normal)) < 0.5
    assert plane.offset_m == pytest.approx(0.73, abs=0.002)
    assert inliers[: len(table)].mean() > 0.99
    assert inliers[len(table) :].mean() < 0.05


def _blobs(rng):
    centres = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.4, 0.1]])
    sizes = [600, 300, 150]
    blobs = [rng.normal(c, 0.01, size=(n, 3)) for c, n in zip(centres, sizes, strict=True)]
    noise = rng.uniform(-1.0, 1.0, size=(30, 3)) + np.array([0.0, 0.0, 2.0])
    return np.concatenate([*blobs, noise]), sizes


def test_ransac_is_reproducible_with_its_seed():
    """open3d samples on several threads, so its plane alone varies between runs with the
    same seed; the fit must not."""
    rng = np.random.default_rng(0)
    table = np.c_[rng.uniform(-0.5, 0.5, (60000, 2)), rng.normal(-0.2, 0.002, 60000)]
    points = np.vstack([table, rng.normal(size=(20000, 3)) * 0.05])
    fits = [fit_table_ransac(points, np.random.default_rng(3)) for _ in range(8)]
    for plane, inliers in fits[1:]:
        assert plane.offset_m == fits[0][0].offset_m
        np.testing.assert_array_equal(plane.normal, fits[0][0].normal)
        np.testing.assert_array_equal(inliers, fits[0][1])


def test_dbscan_matches_open3d_partition():
    points, sizes = _blobs(np.random.default_rng(0))
    ours = dbscan_labels(points, 0.01, 10)
    cloud = open3d().geometry.PointCloud(open3d().utility.Vector3dVector(points))
    theirs = np.asarray(cloud.cluster_dbscan(eps=0.01, min_points=10))
    np.testing.assert_array_equal(ours < 0, theirs < 0)
    clustered = ours >= 0
    # Same partition: the label pairs form a bijection.
    pairs = set(zip(ours[clustered], theirs[clustered], strict=True))
    assert len(pairs) == len(set(ours[clustered])) == len(set(theirs[clustered]))
    largest = largest_cluster_indices(ours)
    assert set(largest) <= set(range(sizes[0])) and len(largest) > 0.9 * sizes[0]


def _dbscan_by_definition(points: np.ndarray, eps_m: float, min_points: int) -> np.ndarray:
    """DBSCAN as :func:`dbscan_labels` defines it, from the full distance matrix."""
    near = np.linalg.norm(points[:, None] - points[None], axis=2) <= eps_m
    core = near.sum(axis=1) >= min_points
    labels = np.full(len(points), -1)
    count = 0
    for start in np.flatnonzero(core):  # components numbered by their first core point
        if labels[start] >= 0:
            continue
        labels[start], frontier = count, [start]
        while frontier:
            reached = np.flatnonzero(near[frontier.pop()] & core & (labels < 0))
            labels[reached] = count
            frontier.extend(reached)
        count += 1
    distance = np.linalg.norm(points[:, None] - points[core][None], axis=2)
    for i in np.flatnonzero(~core):
        if core.any() and distance[i].min() <= eps_m:
            labels[i] = labels[np.flatnonzero(core)[np.argmin(distance[i])]]
    return labels


@pytest.mark.parametrize("min_points", [1, 4, 10])
def test_dbscan_matches_its_definition_with_repeated_points(min_points):
    """Core points, components, their numbering and each border point's nearest core point
    as a dense distance matrix gives them, on a cloud with repeated points (a point's
    neighbours count its copies)."""
    rng = np.random.default_rng(min_points)
    points = np.round(rng.normal(0.0, 0.02, size=(300, 3)), 3)
    points[::7] = points[1::7][: len(points[::7])]
    np.testing.assert_array_equal(
        dbscan_labels(points, 0.008, min_points), _dbscan_by_definition(points, 0.008, min_points)
    )


def test_euclidean_clustering_links_chains():
    chain = np.column_stack([np.arange(10) * 0.009, np.zeros(10), np.zeros(10)])
    far = chain + np.array([1.0, 0.0, 0.0])
    labels = dbscan_labels(np.concatenate([chain, far]), 0.01, 1)
    assert len(set(labels[:10])) == 1 and len(set(labels[10:])) == 1
    assert labels[0] != labels[10]


def test_voxel_subsampling_keeps_one_point_per_voxel():
    rng = np.random.default_rng(1)
    points = rng.uniform(0.0, 0.1, size=(5000, 3))
    kept = voxel_subsample_indices(points, 0.02)
    voxels = np.floor(points / 0.02).astype(int)
    assert len(kept) == len(np.unique(voxels, axis=0))
    assert len(np.unique(voxels[kept], axis=0)) == len(kept)


@pytest.fixture(scope="module")
def box_scene():
    return synthetic_observation(
        box_object(0.042, 0.15, 0.12),
        (0.6, 0.1, 0.4),
        table_height_m=0.7,
        rng=np.random.default_rng(5),
    )


@pytest.mark.parametrize("table", ["known", "ransac"])
def test_table_cluster_recovers_object_points(box_scene, table):
    segmenter = TableCluster(TableCluster.Params(table=table))
    cloud = segmenter.segment(box_scene)
    on_object = box_scene.object_mask[cloud.pixels[:, 0], cloud.pixels[:, 1]]
    precision = on_object.mean()
    # Recall against the object pixels at least 2 cm above the table (exact geometry).
    depth = np.where(box_scene.object_mask, box_scene.depth_m, np.nan)
    points, _ = backproject_depth(depth, box_scene.intrinsics, box_scene.T_robot_camera)
    reachable = int((points[:, 2] >= 0.7 + 0.025).sum())
    assert precision > 0.99
    assert on_object.sum() >= 0.97 * reachable
    # The cut follows the table's noise: the box reaches down to the table, and no further.
    lowest = np.sort(cloud.points[:, 2])[:5]
    assert cloud.frame == "robot" and lowest.min() >= 0.7 and lowest.max() < 0.7 + 0.006
    np.testing.assert_array_equal(cloud.viewpoint_m, box_scene.T_robot_camera[:3, 3])


def test_table_cluster_fails_clearly_on_an_empty_table():
    T = look_at(np.array([0.6, 0.0, 0.7]), 1.0, np.deg2rad(45.0), np.pi)
    sheet = box_object(0.04, 0.04, 0.001)  # a sheet of paper: thinner than any cut
    depth, _ = render_depth(sheet, (0.6, 0.0, 0.0), 0.7, KINECT, T)
    observation = DepthObservation(
        depth, np.zeros((480, 640, 3), np.uint8), KINECT, T, table_height_m=0.7
    )
    with pytest.raises(StageFailure, match=r"table-cluster.*largest cluster has 0 points"):
        TableCluster().segment(observation)


def test_ground_truth_mask_drops_near_table_points_and_needs_a_mask(box_scene):
    cloud = GroundTruthMask().segment(box_scene)
    assert box_scene.object_mask[cloud.pixels[:, 0], cloud.pixels[:, 1]].all()
    assert cloud.points[:, 2].min() >= 0.72
    np.testing.assert_array_equal(cloud.viewpoint_m, box_scene.T_robot_camera[:3, 3])
    without = DepthObservation(
        box_scene.depth_m, box_scene.rgb, box_scene.intrinsics, box_scene.T_robot_camera, 0.7
    )
    with pytest.raises(PluginError, match="no object mask") as error:  # not a failed run
        GroundTruthMask().segment(without)
    assert error.value.exit_code == EXIT_BAD_INPUT


@pytest.mark.parametrize("viewpoint", [[0.0, 1.0], [0.0, np.nan, 1.0]])
def test_a_cloud_refuses_a_viewpoint_that_is_not_a_position(viewpoint):
    with pytest.raises(ValueError, match="viewpoint_m"):
        PointCloud(np.zeros((3, 3)), viewpoint_m=np.array(viewpoint))


def _arc(radius_m, start_deg, stop_deg, z_low, z_high):
    """Points on a vertical cylinder wall about the origin, every 5 deg and 2 mm."""
    a, z = np.meshgrid(
        np.radians(np.arange(start_deg, stop_deg + 1e-9, 5.0)), np.arange(z_low, z_high, 0.002)
    )
    return np.column_stack([radius_m * np.cos(a.ravel()), radius_m * np.sin(a.ravel()), z.ravel()])


def test_a_mugs_near_wall_and_its_inside_seen_over_the_rim_are_one_object():
    # What a camera above the -x side sees of an open mug (radius 40 mm, 80 mm tall, its
    # inside floor 35 mm up): the outside of the near wall and, over the rim, the inside of
    # the far wall and the floor beyond the near wall's shadow. The floor reaches 15 mm
    # from the near wall: two clusters in space, one footprint. A second object stands
    # 16 cm away.
    near = _arc(0.040, 120.0, 240.0, 0.72, 0.80)
    x, y = np.meshgrid(np.arange(-0.025, 0.0301, 0.002), np.arange(-0.015, 0.0151, 0.002))
    floor = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 0.735)])
    inside = np.vstack([_arc(0.036, -60.0, 60.0, 0.735, 0.80), floor])
    other = _arc(0.03, 120.0, 240.0, 0.72, 0.80) + np.array([0.0, 0.16, 0.0])
    points = np.vstack([near, inside, other])
    table = table_from_height(0.7)
    labels = dbscan_labels(points, 0.01, 10)
    assert len(np.unique(labels)) == 3  # apart in space
    merged = merge_overlapping_footprints(points, labels, table)
    parts = np.cumsum([0, len(near), len(inside), len(other)])
    ids = [np.unique(merged[a:b]) for a, b in itertools.pairwise(parts)]
    assert all(len(i) == 1 for i in ids)
    assert ids[0] == ids[1] != ids[2]
    assert sorted(np.unique(merged)) == [0, 1]
    result = segment_points(points, table, min_height_m=0.0)
    assert len(result.objects) == 2
    assert len(result.objects[0]) == len(near) + len(inside)


def test_footprints_within_the_clustering_radius_are_one_object():
    # A mug seen over its rim with its floor and rim hidden: the near wall's outside
    # (radius 40 mm, 88 deg either side of the camera's -x, up to 60 mm) and the far
    # wall's inside (radius 36 mm, 85 deg either side of +x, from 75 mm) are 15 mm apart
    # in space, and their footprints' hulls 4.5 mm apart. A box 12 mm beyond the near
    # wall's hull is another object.
    near = _arc(0.040, 92.0, 268.0, 0.72, 0.76)
    far = _arc(0.036, -85.0, 85.0, 0.775, 0.80)
    x, y, z = np.meshgrid(np.arange(-0.09, -0.0519, 0.002), np.arange(-0.02, 0.0201, 0.002), [0.75])
    box = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    points = np.vstack([near, far, box])
    table = table_from_height(0.7)
    labels = dbscan_labels(points, 0.01, 10)
    assert len(np.unique(labels)) == 3
    parts = np.cumsum([0, len(near), len(far), len(box)])

    def objects(gap_m):
        merged = merge_overlapping_footprints(points, labels, table, gap_m=gap_m)
        return [set(np.unique(merged[a:b]).tolist()) for a, b in itertools.pairwise(parts)]

    apart = objects(0.0)
    assert len(set().union(*apart)) == 3
    walls, far_wall, other = objects(0.01)
    assert walls == far_wall != other


def test_merging_footprints_keeps_noise_and_apart_clusters():
    labels = np.array([0, 0, 0, -1, 1, 1, 1])
    points = np.array(
        [
            [0, 0, 1],
            [0.01, 0, 1],
            [0, 0.01, 1],
            [0.5, 0.5, 1],
            [1, 0, 1],
            [1.01, 0, 1],
            [1, 0.01, 1],
        ],
        dtype=float,
    )
    merged = merge_overlapping_footprints(points, labels, table_from_height(0.0))
    np.testing.assert_array_equal(merged, labels)
