"""Convex regions of a depth image (table-cluster's 'convex' method, symfuse complete's
default): objects stacked on and standing against each other come apart, one object's
own faces stay together."""

from __future__ import annotations

import numpy as np
import pytest
from box_scenes import ray_cast

from pipeline.geometry.poses import look_at
from pipeline.perception.depth import backproject_depth
from pipeline.perception.segmentation import segment_image
from pipeline.perception.surfaces import concave_creases, image_normals
from pipeline.perception.table import table_from_height
from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT
from pipeline.types import CameraIntrinsics

TABLE = ((-0.6, -0.6, -0.03), (0.6, 0.6, 0.0))
HALF = CameraIntrinsics(320, 240, KINECT.fx / 2, KINECT.fy / 2, KINECT.cx / 2, KINECT.cy / 2)


def segmented_boxes(boxes, azimuth_deg: float = 200.0) -> tuple[np.ndarray, list[np.ndarray]]:
    """Each scene point's box (-1 for the table) and the segmented objects' indices."""
    T = look_at(np.array([0.0, 0.0, 0.05]), 0.9, np.deg2rad(40.0), np.deg2rad(azimuth_deg))
    depth = ray_cast([TABLE, *boxes], T)
    points, _ = backproject_depth(depth, HALF, T)
    truth = np.full(len(points), -1)
    for index, (low, high) in enumerate(boxes):
        inside = np.all(
            (points >= np.array(low) - 1e-6) & (points <= np.array(high) + 1e-6), axis=1
        )
        truth[inside & (truth < 0)] = index
    result = segment_image(depth, HALF, T, table_from_height(0.0), min_height_m=0.005)
    return truth, list(result.objects)


def assert_one_object_per_box(truth, objects, count):
    assert len(objects) == count
    for indices in objects:
        boxes, sizes = np.unique(truth[indices], return_counts=True)
        assert sizes.max() / sizes.sum() > 0.95, f"object mixes boxes {boxes} ({sizes})"
    assert len({int(np.bincount(truth[i] + 1).argmax()) for i in objects}) == count


def test_a_box_on_a_box_is_two_objects():
    lower = ((-0.12, -0.1, 0.0), (0.12, 0.1, 0.08))
    upper = ((-0.06, -0.05, 0.08), (0.06, 0.05, 0.2))
    truth, objects = segmented_boxes([lower, upper])
    assert_one_object_per_box(truth, objects, 2)


def test_two_boxes_standing_against_each_other_are_two_objects():
    low = ((-0.1, -0.12, 0.0), (0.1, 0.0, 0.07))
    tall = ((-0.05, 0.0, 0.0), (0.05, 0.08, 0.18))
    truth, objects = segmented_boxes([low, tall], azimuth_deg=180.0)
    assert_one_object_per_box(truth, objects, 2)


def test_a_single_box_is_one_object():
    truth, objects = segmented_boxes([((-0.1, -0.06, 0.0), (0.1, 0.06, 0.15))])
    assert_one_object_per_box(truth, objects, 1)


@pytest.mark.parametrize(("outward", "creased"), [(1.0, False), (-1.0, True)])
def test_a_convex_edge_is_no_crease_and_a_concave_one_is(outward, creased):
    """A ridge (two planes meeting at 90 deg, edge toward the camera) and a valley."""
    cols = np.arange(40)
    x = (cols - 20) * 0.002
    height = outward * -np.abs(x)  # the camera is above, at z = 1 m: a ridge, or a valley
    points = np.zeros((10, 40, 3))
    points[..., 0] = x
    points[..., 1] = (np.arange(10) * 0.002)[:, None]
    points[..., 2] = height
    valid = np.ones((10, 40), bool)
    normals = image_normals(points, valid, 5)
    crease = concave_creases(points, normals, np.array([0.0, 0.0, 1.0]), 3, 0.3)
    assert crease[5, 18:23].any() == creased
    assert not crease[5, :12].any() and not crease[5, 28:].any()
