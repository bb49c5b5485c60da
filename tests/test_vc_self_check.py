"""VC checks its plane against the capture: a plane in front of every visible point and
mirrored points out of view count against it, and an object no vertical mirror plane
fits (an L-shaped block) ends ``asymmetric`` in ``symfuse complete``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from box_scenes import ray_cast, write_capture

from pipeline.cli import main
from pipeline.geometry.poses import look_at
from pipeline.perception.depth import backproject_depth
from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT
from pipeline.types import CameraIntrinsics, DepthObservation, PointCloud
from plugins.initialisers.vc import VcInitialiser, camera_side_share, mirrored_out_of_view

TABLE = ((-0.6, -0.6, -0.03), (0.6, 0.6, 0.0))
#: Two arms of unequal length at right angles: no vertical plane mirrors the footprint.
L_BLOCK = [((-0.12, -0.06, 0.0), (0.12, -0.01, 0.08)), ((-0.12, -0.01, 0.0), (-0.07, 0.10, 0.08))]
BOX = [((-0.12, -0.05, 0.0), (0.12, 0.05, 0.08))]


def test_camera_side_share_by_hand():
    points = np.column_stack([np.linspace(0.0, 1.0, 11), np.zeros(11), np.zeros(11)])
    camera = np.array([-5.0, 0.0, 1.0])
    theta = np.zeros(3)  # normal +x: planes x = offset
    share = camera_side_share(points, theta, np.array([-1.0, 2.0, 0.45]), camera)
    # In front of every point (between them and the camera), behind all, through the middle.
    np.testing.assert_allclose(share, [0.0, 1.0, 5 / 11])


def test_the_share_of_points_mirrored_off_the_image_by_hand():
    k = CameraIntrinsics(width=100, height=100, fx=100.0, fy=100.0, cx=50.0, cy=50.0)
    T = np.eye(4)  # camera at the origin looking along +z of frame R
    points = np.array([[0.0, 0.0, 1.0], [0.2, 0.0, 1.0]])
    # Mirrored in the plane x = 0.1: the points swap; in x = 0.6: x = 1.2 and 1.0, both
    # off the image (|x / z| > 0.5); in x = 0 the second one lands at x = -0.2, in view.
    counts = mirrored_out_of_view(points, np.zeros(3), np.array([0.1, 0.6, 0.0]), k, T)
    np.testing.assert_array_equal(counts, [0.0, 1.0, 0.0])


def block_view(boxes, azimuth_deg: float):
    """The block on the table seen from 0.9 m at 40 deg elevation, every 2nd Kinect pixel."""
    T = look_at(np.zeros(3), 0.9, np.deg2rad(40.0), np.deg2rad(azimuth_deg))
    return T, ray_cast([TABLE, *boxes], T)


def test_a_plane_in_front_of_the_visible_points_is_never_chosen():
    T, depth = block_view(BOX, 200.0)
    k = CameraIntrinsics(320, 240, KINECT.fx / 2, KINECT.fy / 2, KINECT.cx / 2, KINECT.cy / 2)
    observation = DepthObservation(depth, np.zeros((*depth.shape, 3), np.uint8), k, T, 0.0)
    points, pixels = backproject_depth(depth, k, T)
    above = points[:, 2] > 0.005
    cloud = PointCloud(points[above], "robot", pixels[above], T[:3, 3])
    init = VcInitialiser(VcInitialiser.Params(max_offset_m=0.2)).propose(cloud, observation)
    planes = [h.plane for h in init.hypotheses]
    theta = np.array([p.theta_rad for p in planes])
    offset = np.array([p.offset_m for p in planes])
    share = camera_side_share(cloud.points, theta, offset, T[:3, 3])
    in_front = share < 0.02
    assert in_front.any(), "the grid must reach planes in front of the box"
    assert all(h.score == 1.0 for h, front in zip(init.hypotheses, in_front, strict=True) if front)
    assert init.status == "ok" and share[0] >= 0.02


@pytest.mark.slow
@pytest.mark.parametrize(("boxes", "status"), [(L_BLOCK, "asymmetric"), (BOX, "completed")])
def test_an_l_shaped_block_ends_asymmetric_and_a_box_completes(tmp_path, boxes, status):
    _, depth = block_view(boxes, 210.0)
    out = tmp_path / "out"
    assert main(["complete", str(write_capture(tmp_path, depth)), "--out", str(out)]) == 0
    objects = json.loads((out / "objects.json").read_text())["objects"]
    assert [o["status"] for o in objects] == [status]
    assert (out / "object_0" / "completed_stage0.ply").exists() == (status == "completed")
