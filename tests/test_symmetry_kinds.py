"""A vertical axis from one view, the sweep completion and the choice of kind by evidence."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.symmetry.axis_fit import fit_axis, profile_residuals
from pipeline.symmetry.kinds import (
    choose_kind,
    complete,
    free_space_share,
    plane_through_axis,
    plane_through_part,
    sweep,
    swept_share,
)
from pipeline.synthetic import box_object, cylinder_object, synthetic_observation
from pipeline.types import Symmetry, SymmetryPlane
from plugins.initialisers.vc import VcInitialiser
from plugins.segmenters.table_cluster import TableCluster


def half_cylinder(centre_xy, radius, rng, noise=0.0):
    """Points on the front half (facing -x) of a vertical cylinder of height 0.1 m."""
    angle = rng.uniform(math.pi / 2, 3 * math.pi / 2, 2000)
    z = rng.uniform(0.0, 0.1, 2000)
    r = radius + noise * rng.standard_normal(2000)
    return np.column_stack([centre_xy[0] + r * np.cos(angle), centre_xy[1] + r * np.sin(angle), z])


def test_profile_residuals_are_zero_on_a_cone_about_its_axis():
    rng = np.random.default_rng(0)
    z = rng.uniform(0.0, 0.1, 500)
    angle = rng.uniform(0.0, 2.0 * math.pi, 500)
    radius = 0.05 - 0.2 * z  # a taper: every slice has its own radius
    points = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), z])
    # Thin slices: the taper within one is far below the tolerance.
    residuals = profile_residuals(points, np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.001, 3)
    assert np.abs(residuals).max() < 1e-4 + 0.2 * 0.001


def test_the_axis_of_half_a_noisy_cylinder_is_found():
    points = half_cylinder((0.6, 0.05), 0.03, np.random.default_rng(1), noise=0.001)
    fit = fit_axis(points)
    assert fit is not None
    assert np.linalg.norm(fit.axis.point_m[:2] - [0.6, 0.05]) < 0.002
    assert fit.profile_rms_m == pytest.approx(0.001, rel=0.2)


def test_a_box_corner_fits_no_circle():
    rng = np.random.default_rng(2)
    side = rng.uniform(0.0, 0.08, (2, 1000))
    z = rng.uniform(0.0, 0.1, (2, 1000))
    corner = np.vstack(
        [
            np.column_stack([side[0], np.zeros(1000), z[0]]),
            np.column_stack([np.zeros(1000), side[1], z[1]]),
        ]
    )
    # Four times the noise of the cylinder above: no circle through the corner fits.
    assert fit_axis(corner).profile_rms_m > 0.004


def test_sweep_and_mirror_completions():
    points = np.array([[1.0, 0.0, 0.5]])
    axis = Symmetry("axis", [0.0, 0.0, 1.0], [0.0, 0.0, 0.0])
    swept = sweep(points, axis, turns=4)
    assert np.allclose(swept, [[1, 0, 0.5], [0, 1, 0.5], [-1, 0, 0.5], [0, -1, 0.5]])
    plane = Symmetry.from_plane(SymmetryPlane(0.0, 0.25))
    assert np.allclose(complete(points, plane), [[1.0, 0.0, 0.5], [-0.5, 0.0, 0.5]])


def test_the_plane_through_an_axis_faces_the_camera():
    axis = Symmetry("axis", [0.0, 0.0, 1.0], [0.6, 0.1, 0.0])
    plane = plane_through_axis(axis, np.array([-0.4, 0.1, 0.7]))
    assert abs(plane.normal[0]) == pytest.approx(1.0)
    assert plane.normal[:2] @ [0.6, 0.1] == pytest.approx(plane.offset_m)


def view(obj, pose, seed):
    observation = synthetic_observation(obj, pose, rng=np.random.default_rng(seed))
    return observation, TableCluster().segment(observation)


@pytest.mark.parametrize(
    ("obj", "pose", "kind"),
    [
        (cylinder_object(0.0265, 0.12), (0.6, 0.05, 0.0), "axis"),
        (box_object(0.042, 0.15, 0.12), (0.6, 0.0, 0.35), "vertical-plane"),
        (box_object(0.08, 0.08, 0.12), (0.6, 0.0, 0.8), "vertical-plane"),
    ],
)
def test_vc_by_evidence_makes_a_can_an_axis_and_keeps_a_box_a_plane(obj, pose, kind):
    observation, cloud = view(obj, pose, seed=4)
    init = VcInitialiser(VcInitialiser.Params(kind="evidence")).propose(cloud, observation)
    assert init.kind == kind
    assert set(init.kind_scores) == {"vertical-plane", "axis", "plane"}
    if kind == "axis":
        assert np.linalg.norm(init.symmetry.point_m[:2] - pose[:2]) < 0.003
        # The plane the estimator fuses passes through the axis.
        assert abs(init.plane.normal[:2] @ pose[:2] - init.plane.offset_m) < 0.003


def test_the_paper_kind_is_the_default():
    observation, cloud = view(cylinder_object(0.0265, 0.12), (0.6, 0.05, 0.0), seed=4)
    init = VcInitialiser().propose(cloud, observation)
    assert init.kind == "vertical-plane" and init.symmetry is None and init.kind_scores == {}


def test_choose_kind_scores_a_misplaced_axis_by_free_space():
    observation, cloud = view(cylinder_object(0.0265, 0.12), (0.6, 0.05, 0.0), seed=4)
    plane = VcInitialiser().propose(cloud, observation).plane
    choice = choose_kind(
        cloud.points,
        observation,
        plane,
        tolerance_m=0.01,
        max_profile_rms_m=0.0025,
        margin=0.02,
    )
    assert choice.symmetry.kind == "axis"
    assert choice.scores["axis"] < 0.05
    # The same view swept about an axis moved 5 cm toward the camera lands in free space.
    moved = Symmetry("axis", [0.0, 0.0, 1.0], choice.symmetry.point_m - [0.05, 0.0, 0.0])
    assert free_space_share(sweep(cloud.points, moved), observation, 0.01) > 0.2


def test_the_swept_share_checks_the_same_points_as_the_whole_sweep():
    observation, cloud = view(cylinder_object(0.0265, 0.12), (0.6, 0.05, 0.0), seed=4)
    rng = np.random.default_rng(3)
    for points in (cloud.points, cloud.points[:250]):  # subsampled sweep, and all of it
        for _ in range(4):
            direction = rng.normal(size=3)
            axis = Symmetry("axis", direction / np.linalg.norm(direction), points.mean(axis=0))
            table_z = float(rng.uniform(-0.01, 0.03))
            whole = free_space_share(sweep(points, axis), observation, 0.005, table_z)
            assert swept_share(points, axis, observation, 0.005, table_z) == whole


def test_the_plane_through_the_axis_and_a_handle_off_it():
    rng = np.random.default_rng(5)
    body = half_cylinder((0.6, 0.05), 0.04, rng, noise=0.0005)
    # A handle sticking out 30-45 mm from the axis, toward (-1, 1) / sqrt(2).
    reach = rng.uniform(0.045, 0.06, 200)
    handle = np.column_stack(
        [0.6 - reach / math.sqrt(2), 0.05 + reach / math.sqrt(2), rng.uniform(0.03, 0.07, 200)]
    )
    points = np.vstack([body, handle])
    fit = fit_axis(points)
    plane = plane_through_part(points, fit)
    assert plane is not None and plane.kind == "vertical-plane"
    assert abs(plane.direction @ unit_xy(-1.0, 1.0)) < math.sin(math.radians(3.0))
    assert abs(plane.direction @ (np.array([0.6, 0.05, 0.0]) - plane.point_m)) < 0.002
    # The body alone has no part off its axis.
    assert plane_through_part(body, fit_axis(body)) is None


def unit_xy(x, y):
    return np.array([x, y, 0.0]) / math.hypot(x, y)
