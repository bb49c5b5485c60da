"""Depth-sensor error models against the published figures and geometric oracles."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from pipeline.sim.depth_noise import (
    KinectV1Noise,
    StereoNoise,
    discontinuity_mask,
    incidence_angle_rad,
    kinect_v1_dropouts,
    move_edges_laterally,
    shadow_mask,
    simulate_kinect_v1,
    simulate_stereo,
)
from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT
from pipeline.types import CameraIntrinsics

STEREO = CameraIntrinsics(640, 480, 1600.0, 1600.0, 319.5, 239.5)
QUIET_KINECT = KinectV1Noise(axial_noise=False, lateral_noise=False, shadows=False)


def wall(depth_m: float, intrinsics: CameraIntrinsics = KINECT) -> np.ndarray:
    return np.full((intrinsics.height, intrinsics.width), depth_m)


def interior_std(depth: np.ndarray) -> float:
    return float(np.nanstd(depth[10:-10, 10:-10]))


@pytest.mark.parametrize("z_m", [1.0, 2.0])
def test_kinect_flat_wall_sigma_matches_nguyen(z_m):
    # Nguyen, Izadi & Lovell 2012, frontal plane (theta = 0).
    published_sigma_m = 0.0012 + 0.0019 * (z_m - 0.4) ** 2
    simulated = simulate_kinect_v1(wall(z_m), KINECT, np.random.default_rng(1))
    assert interior_std(simulated.depth_m) == pytest.approx(published_sigma_m, rel=0.2)


@pytest.mark.parametrize("z_m", [1.0, 2.0])
def test_kinect_flat_wall_sigma_matches_khoshelham(z_m):
    # Khoshelham & Oude Elberink 2012: sigma_Z = 1.425e-3 Z^2 m.
    noise = KinectV1Noise(axial_model="khoshelham")
    simulated = simulate_kinect_v1(wall(z_m), KINECT, np.random.default_rng(2), noise)
    assert interior_std(simulated.depth_m) == pytest.approx(1.425e-3 * z_m**2, rel=0.2)


@pytest.mark.parametrize("z_m", [1.0, 2.0])
def test_stereo_flat_wall_sigma_is_z_squared_law(z_m):
    noise = StereoNoise(disparity_sigma_px=0.2, baseline_m=0.09)
    simulated = simulate_stereo(wall(z_m, STEREO), STEREO, np.random.default_rng(3), noise)
    expected_m = z_m**2 * 0.2 / (1600.0 * 0.09)
    assert interior_std(simulated.depth_m) == pytest.approx(expected_m, rel=0.2)


def test_kinect_noise_is_unbiased_and_seeded():
    a = simulate_kinect_v1(wall(1.5), KINECT, np.random.default_rng(7)).depth_m
    b = simulate_kinect_v1(wall(1.5), KINECT, np.random.default_rng(7)).depth_m
    np.testing.assert_array_equal(a, b)
    assert abs(np.nanmean(a[10:-10, 10:-10]) - 1.5) < 2e-4


def quantisation_levels(z_centre_m: float) -> np.ndarray:
    """Distinct depths the noiseless Kinect reports for a fine ramp of depths near z."""
    ramp = np.linspace(z_centre_m - 0.03, z_centre_m + 0.03, 640)
    depth = np.tile(ramp, (480, 1))
    measured = simulate_kinect_v1(depth, KINECT, np.random.default_rng(0), QUIET_KINECT).depth_m
    return np.unique(measured[np.isfinite(measured)].astype(np.float64))


def test_kinect_quantisation_steps_grow_with_z_squared():
    step_1m = np.median(np.diff(quantisation_levels(1.0)))
    step_2m = np.median(np.diff(quantisation_levels(2.0)))
    # Kinect v1 disparity quantisation: dz = z^2 / (8 f b): 2.9 mm at 1 m, 11.6 mm at 2 m.
    assert step_1m == pytest.approx(1.0 / (8 * 575.8 * 0.075), rel=0.05)
    assert step_2m == pytest.approx(4.0 / (8 * 575.8 * 0.075), rel=0.05)
    assert step_2m / step_1m == pytest.approx(4.0, rel=0.05)


@pytest.mark.parametrize("z_m", [0.4, 4.5])
def test_kinect_out_of_range_is_nan(z_m):
    measured = simulate_kinect_v1(wall(z_m), KINECT, np.random.default_rng(0)).depth_m
    assert np.isnan(measured).all()


def test_stereo_out_of_range_is_nan_and_in_range_is_not():
    near = simulate_stereo(wall(0.2, STEREO), STEREO, np.random.default_rng(0)).depth_m
    inside = simulate_stereo(wall(1.0, STEREO), STEREO, np.random.default_rng(0)).depth_m
    assert np.isnan(near).all()
    assert np.isfinite(inside).all()


def test_missing_true_depth_stays_missing():
    depth = wall(1.0)
    depth[:, :100] = np.nan
    measured = simulate_kinect_v1(depth, KINECT, np.random.default_rng(0)).depth_m
    assert np.isnan(measured[:, :95]).all()  # lateral jitter moves the silhouette < 4 px


def step_scene(foreground_cols: slice, z_front: float, z_back: float) -> np.ndarray:
    depth = wall(z_back)
    depth[:, foreground_cols] = z_front
    return depth


def oracle_projector_shadow_cols(
    z_front: float, z_back: float, first: int, last: int, baseline_m: float
) -> np.ndarray:
    """Background columns whose segment to the projector at (B, 0, 0) crosses the
    foreground plate (camera x between the outer edges of columns first..last)."""
    f, cx = KINECT.fx, KINECT.cx
    columns = np.arange(KINECT.width)
    x_back = (columns - cx) * z_back / f
    # Point on the segment background point -> projector at depth z_front.
    x_at_front = baseline_m + (x_back - baseline_m) * z_front / z_back
    plate_low, plate_high = (first - 0.5 - cx) * z_front / f, (last + 0.5 - cx) * z_front / f
    crossing = (x_at_front > plate_low) & (x_at_front < plate_high)
    outside_plate = (columns < first) | (columns > last)
    return np.flatnonzero(crossing & outside_plate)


@pytest.mark.parametrize("baseline_m", [0.075, -0.075])
def test_shadow_mask_matches_ray_geometry(baseline_m):
    depth = step_scene(slice(300, 401), 1.0, 1.5)
    hidden = shadow_mask(depth, KINECT.fx, baseline_m)
    expected = oracle_projector_shadow_cols(1.0, 1.5, 300, 400, baseline_m)
    columns = np.flatnonzero(hidden[240])
    assert (hidden == hidden[240]).all()  # every row alike
    assert len(expected) == pytest.approx(14.4, abs=1.0)  # f B (1/1 - 1/1.5) px
    assert abs(len(columns) - len(expected)) <= 1
    assert set(columns) <= set(range(expected.min() - 1, expected.max() + 2))
    # The shadow is on the side away from the projector only.
    assert (columns < 300).all() if baseline_m > 0 else (columns > 400).all()


def test_shadow_mask_hides_surfaces_facing_away_from_projector():
    # Left of column 320 the disparity falls by 2 px per column, so the projector column
    # u - f B / z decreases with u there: the surface turns its back on the projector.
    columns = np.arange(KINECT.width, dtype=float)
    focal_baseline = KINECT.fx * 0.075
    disparity = np.where(columns >= 320, focal_baseline, focal_baseline - 2.0 * (320 - columns))
    depth = np.tile(np.where(disparity > 1.0, focal_baseline / disparity, np.nan), (4, 1))
    hidden = shadow_mask(depth, KINECT.fx, 0.075)
    assert hidden[:, 300:320].all()
    assert not hidden[:, 320:].any()
    assert not hidden[:, :299].any()  # missing depth is never a shadow


def test_discontinuity_mask_marks_both_sides_with_margin():
    depth = step_scene(slice(300, 641), 1.0, 1.5)
    one = discontinuity_mask(depth, KINECT.fx, 0.075, jump_px=1.0, margin_px=1)
    three = discontinuity_mask(depth, KINECT.fx, 0.075, jump_px=1.0, margin_px=3)
    assert set(np.flatnonzero(one[100])) == {299, 300}
    assert set(np.flatnonzero(three[100])) == {297, 298, 299, 300, 301, 302}
    smooth = np.tile(np.linspace(1.0, 1.2, 640), (480, 1))
    assert not discontinuity_mask(smooth, KINECT.fx, 0.075, 1.0, 2).any()


def test_lateral_edge_jitter_follows_gaussian_rounding():
    depth = step_scene(slice(320, 641), 1.0, 1.5)
    rng = np.random.default_rng(11)
    sigma_px = 0.8
    crossed = []
    for _ in range(4):
        _, _, source_cols = move_edges_laterally(
            depth, np.full(depth.shape, sigma_px), KINECT.fx, 0.075, 1.0, rng
        )
        crossed.append(source_cols >= 320)
    crossed = np.concatenate(crossed)
    for column, distance_px in ((319, 0.5), (318, 1.5)):
        expected = norm.sf(distance_px / sigma_px)  # offset rounds across the edge
        assert crossed[:, column].mean() == pytest.approx(expected, abs=0.02)
    # Inside a smooth surface, pixels keep their own depth.
    assert (crossed[:, 100:300] == False).all()  # noqa: E712


def test_incidence_angle_of_tilted_plane_is_analytic():
    normal = np.array([0.3, -0.5, -0.8]) / np.linalg.norm([0.3, -0.5, -0.8])
    rows, cols = np.mgrid[0:480, 0:640]
    rays = np.stack(
        [(cols - KINECT.cx) / KINECT.fx, (rows - KINECT.cy) / KINECT.fy, np.ones(rows.shape)], -1
    )
    depth = -1.0 / (rays @ normal)  # plane n . p = -1
    expected = np.arccos(np.abs(rays @ normal) / np.linalg.norm(rays, axis=-1))
    measured = incidence_angle_rad(depth, KINECT)
    np.testing.assert_allclose(measured[1:-1, 1:-1], expected[1:-1, 1:-1], atol=1e-5)


def tilted_plane(tilt_deg: float) -> np.ndarray:
    """Depth of a plane through (0, 0, 1) m turned by tilt_deg about the camera's y axis."""
    rows, cols = np.mgrid[0:480, 0:640]
    tilt = np.deg2rad(tilt_deg)
    normal = np.array([np.sin(tilt), 0.0, -np.cos(tilt)])
    rays = np.stack(
        [(cols - KINECT.cx) / KINECT.fx, (rows - KINECT.cy) / KINECT.fy, np.ones(rows.shape)], -1
    )
    depth = -np.cos(tilt) / (rays @ normal)
    depth[depth <= 0] = np.nan  # the plane's far side, behind the camera
    return depth


def test_surfaces_beyond_the_maximum_incidence_are_missing():
    quiet = KinectV1Noise(lateral_noise=False, shadows=False, max_incidence_deg=80.0)
    steep = simulate_kinect_v1(tilted_plane(84.0), KINECT, np.random.default_rng(0), quiet)
    assert np.isnan(steep.depth_m[:, 300:330]).all()
    moderate = simulate_kinect_v1(tilted_plane(70.0), KINECT, np.random.default_rng(0), quiet)
    assert np.isfinite(moderate.depth_m[:, 300:330]).all()


def test_grazing_surfaces_are_noisier():
    # A plane tilted 75 deg away from the camera gets the Nguyen grazing term.
    tilt = np.deg2rad(75.0)
    depth = tilted_plane(75.0)
    quiet = KinectV1Noise(lateral_noise=False, shadows=False)
    noisy = simulate_kinect_v1(depth, KINECT, np.random.default_rng(5), quiet).depth_m
    band = slice(300, 330)
    residual = (noisy - depth)[:, band]
    z_m = 1.0  # the band straddles the optical axis, where the plane is 1 m away
    published = (
        0.0012
        + 0.0019 * (z_m - 0.4) ** 2
        + 0.0001 / np.sqrt(z_m) * tilt**2 / (np.pi / 2 - tilt) ** 2
    )
    assert np.nanstd(residual) == pytest.approx(published, rel=0.25)


@pytest.mark.parametrize("tilt_deg", [70.0, 84.0])
def test_kinect_dropouts_are_the_pixels_the_simulated_kinect_leaves_out(tilt_deg):
    """Without noise or edge jitter, the simulated sensor returns nothing exactly where the
    dropouts say: the step's two sides, the projector's shadow, the steep plane."""
    scene = np.minimum(step_scene(slice(200, 300), 0.6, 1.1), tilted_plane(tilt_deg))
    quiet = KinectV1Noise(axial_noise=False, lateral_noise=False)
    measured = simulate_kinect_v1(scene, KINECT, np.random.default_rng(0), quiet)
    dropped = kinect_v1_dropouts(scene, KINECT, quiet)
    # Away from the range limits, where the simulation tests its rounded depth.
    inside = (scene > quiet.min_range_m + 0.01) & (scene < quiet.max_range_m - 0.1)
    np.testing.assert_array_equal(dropped[inside], np.isnan(measured.depth_m)[inside])
    assert dropped[:, 199:201].all() and dropped[:, 299:301].all()
