"""The evidence a mirror plane has in a view: the share of visible points that meet their
own mirror image (pipeline.symmetry.support), by hand and on views of a box; a body of
revolution's front, mirrored onto its back, has its axis as evidence instead."""

from __future__ import annotations

import numpy as np
import pytest
from box_scenes import ray_cast

from pipeline.geometry.poses import look_at
from pipeline.perception.depth import backproject_depth
from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT
from pipeline.symmetry.support import MIN_MIRROR_SUPPORT, axis_supports, mirror_support
from pipeline.types import CameraIntrinsics, Symmetry

PLANE_X0 = Symmetry("vertical-plane", np.array([1.0, 0.0, 0.0]), np.zeros(3))


def test_mirror_support_by_hand():
    # Four points: two mirror pairs about x = 0 (one exact, one 6 mm off), one point on
    # the plane (its own image) and one 40 mm from it (its image 80 mm away).
    points = np.array(
        [
            [-0.05, 0.0, 0.0],
            [0.05, 0.0, 0.0],
            [0.1, 0.2, 0.0],
            [-0.106, 0.2, 0.0],
            [0.0, 0.5, 0.1],
            [0.04, 0.9, 0.0],
        ]
    )
    assert mirror_support(points, PLANE_X0, counterpart_m=0.01) == pytest.approx(5 / 6)
    assert mirror_support(points, PLANE_X0, counterpart_m=0.005) == pytest.approx(3 / 6)
    assert mirror_support(points[5:], PLANE_X0) == 0.0
    assert mirror_support(np.zeros((0, 3)), PLANE_X0) == 0.0
    with pytest.raises(ValueError, match="mirror plane"):
        mirror_support(points, Symmetry("axis", np.array([0.0, 0.0, 1.0]), np.zeros(3)))


def view_cloud(boxes, azimuth_deg: float) -> np.ndarray:
    """The points above the table of boxes on it seen from 0.9 m at 40 deg elevation."""
    table = ((-0.6, -0.6, -0.03), (0.6, 0.6, 0.0))
    T = look_at(np.zeros(3), 0.9, np.deg2rad(40.0), np.deg2rad(azimuth_deg))
    depth = ray_cast([table, *boxes], T)
    k = CameraIntrinsics(320, 240, KINECT.fx / 2, KINECT.fy / 2, KINECT.cx / 2, KINECT.cy / 2)
    points, _ = backproject_depth(depth, k, T)
    return points[points[:, 2] > 0.005]


@pytest.mark.parametrize("azimuth_deg", [180.0, 210.0, 250.0])
def test_a_box_supports_its_plane_and_a_plane_behind_it_does_not(azimuth_deg):
    """A box seen from above: its top lies on both sides of its mirror plane (through its
    middle), so the plane has support; a plane behind the box, which mirrors the whole view
    into the box's shadow, meets nothing of it."""
    cloud = view_cloud([((-0.12, -0.05, 0.0), (0.12, 0.05, 0.08))], azimuth_deg)
    assert mirror_support(cloud, PLANE_X0) > 3 * MIN_MIRROR_SUPPORT
    behind = Symmetry("vertical-plane", np.array([1.0, 0.0, 0.0]), np.array([0.2, 0.0, 0.0]))
    assert mirror_support(cloud, behind) == 0.0


def test_a_cylinders_front_mirrored_onto_its_back_has_its_axis_as_evidence():
    """The front of a can (facing -x, the 120 deg a camera sees well), noisy by 1 mm: the
    plane through its axis across the view (normal +x) meets nothing of the view, but the
    view fits the axis."""
    rng = np.random.default_rng(2)
    angle = rng.uniform(2 * np.pi / 3, 4 * np.pi / 3, 3000)
    radius = 0.04 + 0.001 * rng.standard_normal(3000)
    front = np.column_stack(
        [0.6 + radius * np.cos(angle), radius * np.sin(angle), rng.uniform(0.0, 0.12, 3000)]
    )
    across = Symmetry("vertical-plane", np.array([1.0, 0.0, 0.0]), np.array([0.6, 0.0, 0.0]))
    assert mirror_support(front, across) == 0.0
    assert axis_supports(front, across)
    # A plane 3 cm off the axis is not one of its mirror planes; a box's corner fits no axis.
    off = Symmetry("vertical-plane", np.array([1.0, 0.0, 0.0]), np.array([0.63, 0.0, 0.0]))
    assert not axis_supports(front, off)
    corner = view_cloud([((-0.12, -0.05, 0.0), (0.12, 0.05, 0.08))], 210.0)
    assert not axis_supports(corner, PLANE_X0)
