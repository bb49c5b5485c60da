"""Circle, line and box-thickness fits against independent oracles."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from pipeline.metrics import (
    DeviationSummary,
    box_thickness,
    diameter_error,
    fit_circle_taubin,
    fit_line_irls,
    plane_after_bias,
)
from pipeline.metrics.fits import _median
from pipeline.types import Bias, SymmetryPlane


def _geometric_circle_fit(xy: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, float]:
    """Orthogonal-distance circle fit by scipy (the geometric maximum-likelihood oracle)."""

    def residuals(params: np.ndarray) -> np.ndarray:
        return np.linalg.norm(xy - params[:2], axis=1) - params[2]

    solution = least_squares(residuals, start, xtol=1e-14, ftol=1e-14, gtol=1e-14)
    return solution.x[:2], float(solution.x[2])


def test_taubin_recovers_an_exact_circle():
    angles = np.linspace(0.3, 2.2, 40)
    xy = np.column_stack([0.5 + 0.04 * np.cos(angles), -0.1 + 0.04 * np.sin(angles)])
    fit = fit_circle_taubin(xy)
    np.testing.assert_allclose(fit.centre_xy_m, [0.5, -0.1], atol=1e-12)
    assert fit.radius_m == pytest.approx(0.04, abs=1e-12)


@pytest.mark.parametrize("arc_deg", [120.0, 180.0, 360.0])
def test_taubin_matches_geometric_fit_on_noisy_arcs(arc_deg):
    rng = np.random.default_rng(3)
    angles = rng.uniform(0.0, np.radians(arc_deg), 500)
    radii = 0.04 + rng.normal(0.0, 0.0008, angles.size)
    xy = np.column_stack([0.2 + radii * np.cos(angles), 0.3 + radii * np.sin(angles)])
    fit = fit_circle_taubin(np.column_stack([xy, rng.uniform(0, 0.1, angles.size)]))
    centre, radius = _geometric_circle_fit(xy, np.array([0.25, 0.25, 0.02]))
    # Taubin's bias is O(noise^2 / R): far below the 0.8 mm noise.
    np.testing.assert_allclose(fit.centre_xy_m, centre, atol=1e-4)
    assert fit.radius_m == pytest.approx(radius, abs=1e-4)
    assert abs(fit.radius_m - 0.04) < 5e-4


def test_diameter_error_and_degenerate_input():
    angles = np.linspace(0.0, np.pi, 30)
    xy = 0.03 * np.column_stack([np.cos(angles), np.sin(angles)])
    assert diameter_error(xy, 0.08) == pytest.approx(0.02, abs=1e-12)
    with pytest.raises(ValueError, match="collinear"):
        fit_circle_taubin(np.column_stack([np.linspace(0, 1, 10), np.linspace(0, 2, 10)]))


def _outlier_line(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, float]:
    """700 inliers on y = 0.3 x + 0.02 (0.5 mm noise) and 300 outliers clustered above."""
    x = rng.uniform(-0.05, 0.05, 700)
    inliers = np.column_stack([x, 0.3 * x + 0.02 + rng.normal(0.0, 5e-4, x.size)])
    outliers = np.column_stack([rng.uniform(0.0, 0.05, 300), rng.uniform(0.05, 0.08, 300)])
    direction = np.array([1.0, 0.3]) / np.hypot(1.0, 0.3)
    return np.vstack([inliers, outliers]), direction, 0.02


def test_irls_recovers_line_with_30_percent_outliers_where_ols_fails():
    xy, direction, intercept = _outlier_line(np.random.default_rng(7))
    fit = fit_line_irls(xy)
    assert abs(abs(fit.direction @ direction) - 1.0) < 1e-4  # < 0.8 deg
    # Where the fitted line crosses x = 0:
    y0 = fit.point_m[1] - fit.point_m[0] * fit.direction[1] / fit.direction[0]
    assert y0 == pytest.approx(intercept, abs=5e-4)
    assert np.count_nonzero(fit.weights[700:]) == 0
    slope_ols, intercept_ols = np.polyfit(xy[:, 0], xy[:, 1], 1)
    assert abs(slope_ols - 0.3) > 0.1 or abs(intercept_ols - intercept) > 0.005


def test_irls_exact_line_and_bad_input():
    t = np.linspace(-1.0, 1.0, 50)
    fit = fit_line_irls(np.column_stack([1.0 + 0.0 * t, t]))  # the vertical line x = 1
    np.testing.assert_allclose(np.abs(fit.direction), [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(fit.distances(np.array([[3.0, 0.0]])) ** 2, [4.0], atol=1e-12)
    with pytest.raises(ValueError, match="distinct"):
        fit_line_irls(np.zeros((5, 2)))


@pytest.mark.parametrize("count", [7, 8, 2000])
def test_robust_line_median_is_numpys_bit_for_bit(count):
    """The fits' median from one partition (rows of candidates, or one residual vector)
    against numpy's, odd and even counts, with repeated values."""
    values = np.round(np.random.default_rng(count).normal(size=(30, count)), 2) ** 2
    assert np.array_equal(_median(values), np.median(values, axis=-1))
    assert np.array_equal(_median(values[3]), np.median(values[3]))


def _box_outline(rng, thickness, half_width, angle_back_rad, n=400):
    """Front face y = 0 and back face through (0, thickness) tilted by angle_back_rad, plus
    some side-face points on the front part, all with 0.3 mm noise."""
    x = rng.uniform(-half_width, half_width, n)
    front = np.column_stack([x, rng.normal(0.0, 3e-4, n)])
    back_dir = np.array([np.cos(angle_back_rad), np.sin(angle_back_rad)])
    back = np.array([0.0, thickness]) + x[:, None] * back_dir
    back += rng.normal(0.0, 3e-4, back.shape)
    side = np.column_stack([np.full(60, half_width), rng.uniform(0.0, 0.4 * thickness, 60)])
    return np.vstack([front, side, back])


def test_box_thickness_of_a_true_box_with_side_face_points():
    rng = np.random.default_rng(11)
    xy = _box_outline(rng, 0.042, 0.07, 0.0)
    plane = SymmetryPlane.from_normal(np.array([0.0, -1.0]), -0.021)  # y = 0.021, front y<
    fit = box_thickness(np.column_stack([xy, np.zeros(len(xy))]), plane, np.array([0.0, 0.021]))
    assert fit.thickness_m == pytest.approx(0.042, abs=3e-4)
    assert fit.angle_rad == pytest.approx(0.0, abs=np.radians(0.5))


def test_box_thickness_with_tilted_back_face():
    rng = np.random.default_rng(12)
    angle = np.radians(6.0)
    xy = _box_outline(rng, 0.044, 0.06, angle, n=800)
    plane = SymmetryPlane(theta_rad=np.pi / 2, offset_m=0.022)
    centre = np.array([0.01, 0.02])
    fit = box_thickness(xy, plane, centre)
    assert fit.angle_rad == pytest.approx(angle, abs=np.radians(0.3))
    # Oracle: the line through the centre along the bisector normal of the two faces,
    # intersected with front (y = 0) and back (through (0, t) along angle).
    across = np.array([-np.sin(angle / 2), np.cos(angle / 2)])
    s_front = -centre[1] / across[1]
    back_normal = np.array([-np.sin(angle), np.cos(angle)])
    s_back = (0.044 * back_normal[1] - centre @ back_normal) / (across @ back_normal)
    assert fit.thickness_m == pytest.approx(abs(s_back - s_front), abs=4e-4)


def test_box_thickness_needs_both_sides():
    xy = np.column_stack([np.linspace(0, 1, 10), np.ones(10)])
    with pytest.raises(ValueError, match="both sides"):
        box_thickness(xy, SymmetryPlane(theta_rad=np.pi / 2, offset_m=5.0), np.zeros(2))


def test_plane_after_bias_is_the_symmetry_plane_of_the_moved_model():
    rng = np.random.default_rng(5)
    points = rng.normal(size=(50, 3))
    plane = SymmetryPlane(theta_rad=0.7, offset_m=0.3)
    bias = Bias(yaw_rad=0.4, translation_m=[0.1, -0.2, 0.05], pivot_m=[1.0, 2.0, 0.0])
    moved_plane = plane_after_bias(plane, bias)
    # f_b(f_m(p)) must be the mirror image of f_b(p) across the moved plane.
    np.testing.assert_allclose(
        moved_plane.mirror(bias.apply(points)), bias.apply(plane.mirror(points)), atol=1e-12
    )


def test_deviation_summary_of_known_values():
    summary = DeviationSummary.from_distances(np.arange(101.0))
    assert (summary.min, summary.q1, summary.median, summary.q3, summary.max) == (
        0.0,
        25.0,
        50.0,
        75.0,
        100.0,
    )
    assert summary.mean == 50.0 and summary.count == 101
    with pytest.raises(ValueError):
        DeviationSummary.from_distances(np.array([]))


def test_side_wall_drops_the_cap_so_the_circle_fit_is_unbiased():
    """A 53 mm cylinder's side wall plus its filled top cap: the cap shrinks a fit to all
    points; the side wall alone gives the true diameter."""
    from pipeline.metrics import fit_circle_taubin, side_wall

    rng = np.random.default_rng(4)
    angle = rng.uniform(0, 2 * np.pi, 4000)
    wall = np.column_stack([0.0265 * np.cos(angle), 0.0265 * np.sin(angle),
                            rng.uniform(0, 0.13, 4000)])  # fmt: skip
    radius = 0.0265 * np.sqrt(rng.uniform(0, 1, 3000))
    cap_angle = rng.uniform(0, 2 * np.pi, 3000)
    cap = np.column_stack([radius * np.cos(cap_angle), radius * np.sin(cap_angle),
                           np.full(3000, 0.13)])  # fmt: skip
    cloud = np.vstack([wall, cap])
    assert fit_circle_taubin(cloud).diameter_m < 0.050
    kept = side_wall(cloud)
    assert np.all(kept[:, 2] < 0.13 - 0.005)
    assert fit_circle_taubin(kept).diameter_m == pytest.approx(0.053, abs=1e-4)
