"""The support plane of a capture without a robot frame: the table, not the wall behind it;
no support (a lone carton) is exit 2; a room scan never raises."""

from __future__ import annotations

import numpy as np
import pytest
from box_scenes import points_camera, ray_cast, write_capture

from pipeline.cli import main
from pipeline.geometry.poses import look_at
from pipeline.perception.clustering import voxel_subsample_indices
from pipeline.perception.segmentation import merge_overlapping_footprints
from pipeline.perception.support import fit_support_plane
from pipeline.perception.table import table_from_height

#: Robot-frame boxes ``(low corner, high corner)`` and the camera of each scene.
TABLE = ((-0.5, -0.8, -0.03), (0.8, 0.8, 0.0))
WALL = ((1.0, -3.0, -0.8), (1.05, 3.0, 2.5))
MUG_SIZED_BOX = ((0.0, -0.04, 0.0), (0.08, 0.04, 0.1))


@pytest.fixture(scope="module")
def wall_scene():
    T = look_at(np.array([0.3, 0.0, 0.0]), 0.9, np.deg2rad(15.0), np.pi)
    return T, ray_cast([TABLE, WALL, MUG_SIZED_BOX], T)


def test_the_table_is_the_support_not_the_wall_behind_it(wall_scene):
    T, depth = wall_scene
    points = points_camera(depth)
    up_camera = T[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    # By area (the voxel grid the planes are found on) the wall dominates the view.
    robot = points[voxel_subsample_indices(points, 0.01)] @ T[:3, :3].T + T[:3, 3]
    assert np.sum(robot[:, 0] > 0.999) > np.sum(np.abs(robot[:, 2]) < 1e-3)
    plane = fit_support_plane(points)
    assert plane.normal @ up_camera == pytest.approx(1.0, abs=1e-6)
    camera_height = T[2, 3]
    assert -plane.offset_m == pytest.approx(camera_height, abs=1e-4)


def test_a_lone_carton_has_no_support_and_complete_exits_2(tmp_path, capsys):
    T = look_at(np.array([0.04, 0.0, 0.05]), 0.7, np.deg2rad(30.0), np.deg2rad(200.0))
    depth = ray_cast([((0.0, -0.1, 0.0), (0.15, 0.1, 0.25))], T)
    with pytest.raises(ValueError, match="support"):
        fit_support_plane(points_camera(depth), min_fraction=0.05)
    code = main(["complete", str(write_capture(tmp_path, depth)), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no support plane" in err[0]


def test_a_room_scan_never_raises(tmp_path, capsys):
    """A floor with furniture and walls: the floor is the support, the furniture is
    objects or set aside at the edge of the view; never a traceback (exit 4)."""
    furniture = [
        ((-3.0, -3.0, -0.05), (3.0, 3.0, 0.0)),
        ((2.0, -3.0, 0.0), (2.05, 3.0, 2.5)),
        ((-3.0, 1.5, 0.0), (3.0, 1.55, 2.5)),
        ((0.5, -0.6, 0.0), (1.2, 0.2, 0.75)),
        ((0.6, 0.5, 0.0), (1.0, 0.9, 0.45)),
    ]
    T = look_at(np.array([1.0, 0.0, 0.3]), 2.5, np.deg2rad(30.0), np.pi)
    depth = ray_cast(furniture, T)
    code = main(["complete", str(write_capture(tmp_path, depth)), "--out", str(tmp_path / "o")])
    assert code in (0, 3), capsys.readouterr().err


def test_merging_footprints_of_nothing_but_noise_is_noise():
    points = np.random.default_rng(0).uniform(-1.0, 1.0, (20, 3))
    labels = np.full(20, -1)
    merged = merge_overlapping_footprints(points, labels, table_from_height(0.0), gap_m=0.01)
    np.testing.assert_array_equal(merged, labels)
