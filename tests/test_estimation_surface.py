"""The surface-orientation filter of the correspondences on a box seen from above."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.estimation.correspondences import PointIndex, find_correspondences
from pipeline.estimation.covariances import normal_ellipsoids
from pipeline.estimation.surface import UNKNOWN_BAND, compatible, elevation_bands, point_bands

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


def test_points_away_from_edges_get_their_face_band():
    points, sides = _box_cloud()
    bands = point_bands(points)
    interior_side = (points[:sides, 2] < TOP_Z_M - 0.012) & (np.abs(points[:sides, 1]) < 0.048)
    interior_top = (points[sides:, 0] > 0.012) & (points[sides:, 0] < 0.033)
    side_bands = bands[:sides][interior_side]
    top_bands = bands[sides:][interior_top]
    assert np.mean(side_bands == 0) > 0.9
    assert np.mean(top_bands == 5) > 0.9


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
