"""Where Stage 1 starts: the truncated distance field against a brute-force one, the
translation grid, and the coarse search recovering a bias the generator applied."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pipeline.estimation.bias_search import (
    DistanceField,
    SearchSettings,
    scored_taxels,
    search_start,
    translation_grid,
    truncated_squared_distances,
)
from pipeline.estimation.hypotheses import HYPOTHESES, held_problem
from pipeline.estimation.iekf import fuse
from pipeline.estimation.map_params import fusion_problem
from pipeline.synthetic import make_case
from plugins.estimators.iekf import IekfEstimator


def test_distance_field_is_within_a_voxel_of_the_brute_force_distance():
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.03, 0.03, (400, 3))
    queries = rng.uniform(-0.05, 0.05, (2000, 3))
    voxel, limit = 0.002, 0.008
    field = DistanceField.build(points, voxel, limit)
    brute = np.linalg.norm(queries[:, None, :] - points[None, :, :], axis=2).min(axis=1)
    expected = np.minimum(brute, limit)
    # Marking voxels moves each point by up to half a voxel diagonal, and interpolating
    # between centres adds up to another.
    assert np.max(np.abs(field(queries) - expected)) <= math.sqrt(3.0) * voxel
    assert field(np.array([[1.0, 1.0, 1.0]]))[0] == limit  # far outside the grid
    assert field(points[:5]).max() <= math.sqrt(3.0) * voxel


@pytest.mark.parametrize("seed", range(4))
def test_truncated_distances_match_the_whole_distance_transform_within_the_radius(seed):
    """scipy's exact Euclidean distance transform is the oracle: equal within the radius
    (bit for bit: both take the root of an integer sum of squares), beyond it inf."""
    from scipy.ndimage import distance_transform_edt

    rng = np.random.default_rng(seed)
    shape = tuple(int(n) for n in rng.integers(1, 30, 3))
    count = int(rng.integers(1, 60))
    cells = np.column_stack([rng.integers(0, n, count) for n in shape])
    radius = int(rng.integers(0, 7))
    free = np.ones(shape, dtype=bool)
    free[tuple(cells.T)] = False
    exact = distance_transform_edt(free)
    found = np.sqrt(truncated_squared_distances(cells, shape, radius))
    within = exact <= radius
    assert np.array_equal(found[within], exact[within])
    assert np.all(np.isinf(found[~within]))


def test_translation_grid_fills_the_prior_ellipse_from_its_centre():
    covariance = np.diag([0.01**2, 0.02**2])
    offsets = translation_grid(covariance, 3.0, 0.005)
    assert np.array_equal(offsets[0], [0.0, 0.0])
    d2 = np.einsum("ki,ij,kj->k", offsets, np.linalg.inv(covariance), offsets)
    assert np.all(d2 <= 9.0 + 1e-12)
    assert np.max(np.abs(offsets[:, 0])) == pytest.approx(0.03)
    assert np.max(np.abs(offsets[:, 1])) == pytest.approx(0.06)
    assert np.allclose(np.round(offsets / 0.005), offsets / 0.005)


def test_scored_taxels_spread_over_every_pad():
    pads = np.array(["a"] * 10 + ["b"] * 3)
    chosen = scored_taxels(np.zeros((13, 3)), pads, 4)
    assert chosen.tolist() == [0, 3, 6, 9, 10, 11, 12]


def _fusion(case):
    params = IekfEstimator().params
    window = (params.window_along_normal_m, params.window_across_normal_m)
    return fusion_problem(case.problem, params, "iekf", window, True)


@pytest.mark.parametrize(
    ("gripper", "tactile_deg", "direction_deg"),
    [("three_finger", 271.3, 109.2), ("three_finger", 0.0, 200.0), ("parallel", 20.0, 300.0)],
)
def test_search_finds_a_bias_several_prior_stds_off(gripper, tactile_deg, direction_deg):
    case = make_case(
        np.random.default_rng(3),
        gripper=gripper,
        tactile_angle_rad=math.radians(tactile_deg),
        theta_error_rad=math.radians(25.0),
        r_error_m=0.009,
        bias_magnitude_m=0.035,
        bias_direction_rad=math.radians(direction_deg),
    )
    fusion = _fusion(case)
    start = search_start(fusion, SearchSettings())
    error = start[1:3] - case.true_bias.translation_m[:2]
    if gripper == "parallel":
        # Flat jaws on a cylinder feel a shift along their faces only through the
        # curvature (1.4 mm at 15 mm): the search is held to the grasp's axis.
        normal = case.contacts.normals[0, :2]
        error = error @ normal
    # 3.5 prior stds away; within one and a half steps of the 5 mm grid.
    assert np.linalg.norm(error) < 0.0075
    assert start[0] == fusion.g_init[0] and start[3] == fusion.g_init[3]


def test_stage_one_from_the_searched_start_converges_where_stage_zeros_diverges():
    case = make_case(
        np.random.default_rng(0),
        gripper="three_finger",
        tactile_angle_rad=math.radians(271.3),
        theta_error_rad=math.radians(24.2),
        r_error_m=0.0087,
        bias_magnitude_m=0.035,
        bias_direction_rad=math.radians(109.2),
    )
    fusion = _fusion(case)
    settings = IekfEstimator().settings()
    (paper,) = fuse(fusion, dataclasses.replace(settings, start_search=False), last_stage=1)
    (searched,) = fuse(fusion, settings, last_stage=1)
    assert paper.status == "diverged"
    assert searched.status == "converged"
    assert np.linalg.norm(searched.g[1:3] - case.true_bias.translation_m[:2]) < 0.004


def test_a_held_component_is_not_searched():
    case = make_case(
        np.random.default_rng(1),
        gripper="three_finger",
        theta_error_rad=math.radians(30.0),
        bias_magnitude_m=0.02,
        bias_direction_rad=1.0,
    )
    fusion = held_problem(_fusion(case), HYPOTHESES["held-plane"])
    start = search_start(fusion, SearchSettings())
    assert np.array_equal(start[4:], fusion.g_init[4:])


def test_no_taxels_start_at_stage_zero():
    case = make_case(np.random.default_rng(2), bias_magnitude_m=0.02, bias_direction_rad=0.0)
    fusion = _fusion(case)
    empty = dataclasses.replace(
        fusion.grasps[0],
        positions_m=np.empty((0, 3)),
        pads=np.empty(0, dtype=str),
    )
    assert np.array_equal(
        search_start(dataclasses.replace(fusion, grasps=(empty,)), SearchSettings()),
        fusion.g_init,
    )
