"""The surface-orientation filter of the correspondences on a box seen from above."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.estimation.correspondences import PointIndex, find_correspondences
from pipeline.estimation.covariances import normal_ellipsoids
from pipeline.estimation.geometry import apply_bias, apply_mirror_bias
from pipeline.estimation.surface import (
    AZIMUTH_BANDS,
    ELEVATION_BANDS,
    UNKNOWN_BAND,
    compatible,
    elevation_bands,
    facing_labels,
    point_labels,
)

#: Box 45 (x) x 120 (y) x 100 (z) mm standing on z = 0; the camera sees the x = 0 face and the
#: top, with about 2 mm between points.
SIDE_X_M, TOP_Z_M = 0.0, 0.1


def _box_cloud(seed=0):
    rng = np.random.default_rng(seed)
    side = np.column_stack(
        [np.zeros(3000), rng.uniform(-0.06, 0.06, 3000), rng.uniform(0.02, TOP_Z_M, 3000)]
    )
    top = np.column_stack(
        [rng.uniform(0.0, 0.045, 1350), rng.uniform(-0.06, 0.06, 1350), np.full(1350, TOP_Z_M)]
    )
    points = np.vstack([side, top])
    return points + rng.normal(0.0, 0.0003, points.shape), len(side)


def test_elevation_bands_of_analytic_normals():
    normals = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [np.cos(0.5), 0.0, np.sin(0.5)]])
    np.testing.assert_array_equal(elevation_bands(normals), [0, 5, 1])  # 0, 90, 28.6 deg
    assert compatible(np.array([0, 2, 3, UNKNOWN_BAND]), 0).tolist() == [True, True, False, True]


def test_points_away_from_edges_get_their_face_label():
    points, sides = _box_cloud()
    labels = point_labels(points)
    interior_side = (points[:sides, 2] < TOP_Z_M - 0.012) & (np.abs(points[:sides, 1]) < 0.048)
    interior_top = (points[sides:, 0] > 0.012) & (points[sides:, 0] < 0.033)
    side_labels = labels[:sides][interior_side]
    top_labels = labels[sides:][interior_top]
    # Side face: horizontal normal along +-x (azimuth 0 or 180 deg, the same direction), so
    # compatible with a taxel facing x and not with one facing y. Top: band 5, any azimuth.
    facing_x, facing_y = facing_labels(np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]))
    assert np.mean((side_labels != UNKNOWN_BAND) & compatible(side_labels, facing_x)) > 0.9
    assert not np.any((side_labels != UNKNOWN_BAND) & compatible(side_labels, facing_y))
    assert np.mean(top_labels == 5 + ELEVATION_BANDS * AZIMUTH_BANDS) > 0.9


@pytest.mark.parametrize("need_pairs", [False, True])
def test_top_row_taxel_is_explained_by_the_face_it_touches(need_pairs):
    """A taxel 4 mm below the top edge of the seen face, wide gates: with the filter its
    weighted mean stays on the face (x = 0); without it the top face drags it inside."""
    points, _ = _box_cloud(seed=1)
    taxel = np.array([[SIDE_X_M, 0.0, TOP_Z_M - 0.004]])
    normal = np.array([[1.0, 0.0, 0.0]])
    window = normal_ellipsoids(normal, 0.003, 0.0017)
    state_covariance = np.diag([0.05, 0.01, 0.01, 0.01, 0.03, 0.4]) ** 2
    g = np.array([0.0, 0.0, 0.0, 0.0, 0.2, 0.0])  # plane far away: only the front counts
    means = {}
    for filtered in (True, False):
        found = find_correspondences(
            PointIndex(points),
            points,
            g,
            points.mean(axis=0),
            taxel,
            window,
            state_covariance,
            alternative=False,
            need_pairs=need_pairs,
            taxel_normals=normal if filtered else None,
        )
        means[filtered] = found.front.weighted_sum[0] / found.front.mass[0]
    assert abs(means[True][0] - SIDE_X_M) < 0.001
    assert means[False][0] - SIDE_X_M > 0.002


def _horizontal(azimuth_deg):
    angle = np.radians(azimuth_deg)
    return np.array([[np.cos(angle), np.sin(angle), 0.0]])


def test_facing_labels_compare_unsigned_azimuths_within_45_deg():
    taxel = facing_labels(_horizontal(0.0))
    # 40 deg and 170 deg (10 deg from the reversed direction) face like it; 50 and 120 do not.
    others = facing_labels(np.vstack([_horizontal(a) for a in (40.0, 170.0, 50.0, 120.0)]))
    assert compatible(others, taxel).tolist() == [True, True, False, False]
    # A steep normal (60 deg elevation) and a label without azimuth match any azimuth.
    steep = facing_labels(np.array([[0.5 * np.cos(1.0), 0.5 * np.sin(1.0), np.sqrt(0.75)]]))
    assert steep[0] // ELEVATION_BANDS == AZIMUTH_BANDS
    anywhere = facing_labels(_horizontal(50.0), with_azimuth=False)
    assert compatible(anywhere, taxel).tolist() == [True]
    assert compatible(facing_labels(_horizontal(50.0)), taxel).tolist() == [False]


def _front_and_back_mass(points, taxel_m, normal, g, need_pairs):
    found = find_correspondences(
        PointIndex(points),
        points,
        g,
        points.mean(axis=0),
        taxel_m[None],
        normal_ellipsoids(normal, 0.003, 0.0017),
        np.diag([0.05, 0.01, 0.01, 0.01, 0.03, 0.4]) ** 2,
        alternative=False,
        need_pairs=need_pairs,
        taxel_normals=normal,
    )
    return found.front.mass[0], found.back.mass[0]


@pytest.mark.parametrize("need_pairs", [False, True])
def test_front_azimuth_is_compared_after_the_bias_yaw(need_pairs):
    """A taxel on the seen face (normal +-x) whose normal is 60 deg off does not weigh the
    front; once the bias turns the front by those 60 deg about the pivot, a taxel at the
    turned face with the turned normal does, and one with the unturned normal does not."""
    points, _ = _box_cloud(seed=2)
    on_face = np.array([SIDE_X_M, 0.0, 0.06])
    g = np.array([0.0, 0.0, 0.0, 0.0, 0.2, 0.0])  # plane far away: only the front counts
    assert _front_and_back_mass(points, on_face, _horizontal(0.0), g, need_pairs)[0] > 0.0
    assert _front_and_back_mass(points, on_face, _horizontal(60.0), g, need_pairs)[0] == 0.0
    turned = g.copy()
    turned[0] = np.radians(60.0)
    moved = apply_bias(on_face[None], turned, points.mean(axis=0))[0]
    assert _front_and_back_mass(points, moved, _horizontal(60.0), turned, need_pairs)[0] > 0.0
    assert _front_and_back_mass(points, moved, _horizontal(0.0), turned, need_pairs)[0] == 0.0


@pytest.mark.parametrize("need_pairs", [False, True])
def test_back_ignores_the_azimuth(need_pairs):
    """The mirrored face 20 mm behind the seen one weighs a taxel whose normal is 60 deg off
    (the back's orientation follows the uncertain plane angle); the front does not."""
    points, _ = _box_cloud(seed=3)
    g = np.array([0.0, 0.0, 0.0, 0.0, 0.01, 0.0])  # plane x = 10 mm: the face mirrors to 20 mm
    behind = apply_mirror_bias(np.array([[SIDE_X_M, 0.0, 0.06]]), g, points.mean(axis=0))[0]
    front, back = _front_and_back_mass(points, behind, _horizontal(60.0), g, need_pairs)
    assert front == 0.0
    assert back > 0.0
