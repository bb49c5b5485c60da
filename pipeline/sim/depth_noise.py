"""Depth-sensor error models: Kinect v1 (structured light) and a narrow-angle stereo pair.

Pure numpy/scipy kernels on depth images; no simulator and no file I/O. Every function takes
the *true* depth along the optical axis, ``(H, W)`` metres with ``NaN`` where no surface is
seen, and returns depth the way the sensor would report it, ``NaN`` where it returns nothing.

Both sensors triangulate: depth ``z`` and disparity ``d`` (pixels) are related by
``d = f B / z`` with ``f`` the focal length (px) and ``B`` the baseline (m) between the camera
and the second viewpoint (the Kinect's IR projector, or the stereo pair's right camera), which
sits at ``+B`` along the camera's x axis (OpenCV optical frame; a negative ``B`` puts it on
the left). Noise is added to the disparity and the disparity is rounded to the sensor's
sub-pixel step, so the depth step grows as ``z^2 step / (f B)`` and the depth error as
``z^2 sigma_d / (f B)``.

Kinect v1 numbers (published calibrations of the sensor):

* Nguyen, Izadi & Lovell 2012, "Modeling Kinect sensor noise for improved 3D reconstruction
  and tracking" (3DIMPVT): axial ``sigma_z(z, theta) = 0.0012 + 0.0019 (z - 0.4)^2`` m, plus
  ``0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2`` m for ``theta > 60 deg``; lateral
  ``sigma_L = 0.8 + 0.035 theta / (pi/2 - theta)`` px, where ``theta`` is the angle between
  the viewing ray and the surface normal.
* Khoshelham & Oude Elberink 2012, "Accuracy and resolution of Kinect depth data for indoor
  mapping applications" (Sensors 12(2)): random error ``sigma_Z = z^2 sigma_d / (f B)`` with
  a disparity error of 0.5 in the Kinect's 1/8-pixel disparity units (1/16 px), about
  1.4 mm at 1 m; disparity measured in steps of 1/8 px.

The model's sigma is the *total* axial error, quantisation included: the Gaussian added before
rounding has variance ``sigma_d^2 - step^2 / 12`` (Sheppard's correction), so a flat wall's
measured standard deviation matches the published curve.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from pipeline.sim.kinect import axial_sigma_m
from pipeline.types import CameraIntrinsics

#: Largest incidence angle used in the Nguyen terms (their ``pi/2 - theta`` denominators
#: diverge at grazing incidence), radians.
MAX_INCIDENCE_RAD = np.deg2rad(89.0)


@dataclass(frozen=True)
class KinectV1Noise:
    """Parameters of the Kinect v1 model (defaults: the published figures above).

    Attributes:
        baseline_m: projector-to-camera distance along the camera x axis (m; Kinect v1:
            75 mm, projector on the camera's right as seen from behind the sensor).
        disparity_step_px: disparity resolution (px; 1/8 for the Kinect's 11-bit disparity).
        min_range_m, max_range_m: usable depth range (m); depth outside is missing.
        axial_model: ``"nguyen"`` (sigma_z(z, theta), Nguyen et al. 2012) or
            ``"khoshelham"`` (sigma_z = z^2 sigma_d / (f B), Khoshelham & Elberink 2012).
        disparity_sigma_px: disparity error for the ``"khoshelham"`` model (px; 0.5 of the
            1/8-px units = 0.0625 px).
        axial_noise: add the axial (disparity) noise; False leaves only the quantisation.
        lateral_noise: jitter depth edges laterally by sigma_L(theta) (Nguyen et al.).
        shadows: drop pixels the projector cannot illuminate (occluded from the projector).
        max_incidence_deg: surfaces seen at a larger angle between ray and normal return
            nothing (deg; Nguyen et al.'s fit covers up to about 80 deg, and its grazing term
            exceeds 6 mm there).
        edge_jump_px: a disparity jump larger than this between 4-neighbours is a depth
            discontinuity (px).
        edge_margin_px: pixels within this distance of a discontinuity are missing (px).
    """

    baseline_m: float = 0.075
    disparity_step_px: float = 0.125
    min_range_m: float = 0.5
    max_range_m: float = 4.0
    axial_model: Literal["nguyen", "khoshelham"] = "nguyen"
    disparity_sigma_px: float = 0.0625
    axial_noise: bool = True
    lateral_noise: bool = True
    shadows: bool = True
    max_incidence_deg: float = 80.0
    edge_jump_px: float = 1.0
    edge_margin_px: int = 1


@dataclass(frozen=True)
class StereoNoise:
    """Parameters of the stereo model (defaults: a narrow-angle pair like Armar III's).

    Attributes:
        baseline_m: distance to the right camera along the left camera's x axis (m;
            about 90 mm on the Armar III head, unconfirmed).
        disparity_sigma_px: total disparity error of the matcher (px).
        disparity_step_px: sub-pixel disparity resolution of the matcher (px; 1/16 as in
            semi-global block matching).
        min_range_m, max_range_m: depth range the disparity search covers (m).
        axial_noise: add the disparity noise; False leaves only the quantisation.
        occlusions: drop pixels the right camera cannot see (left-right occlusion).
        edge_jump_px: a disparity jump larger than this is a depth discontinuity (px).
        edge_margin_px: pixels within this distance of a discontinuity are missing (px;
            about half the matching window).

    Matching failures on untextured surfaces are not modelled: every visible, unoccluded
    pixel away from an edge returns a depth.
    """

    baseline_m: float = 0.09
    disparity_sigma_px: float = 0.2
    disparity_step_px: float = 1.0 / 16.0
    min_range_m: float = 0.3
    max_range_m: float = 3.0
    axial_noise: bool = True
    occlusions: bool = True
    edge_jump_px: float = 1.0
    edge_margin_px: int = 2


@dataclass(frozen=True)
class SimulatedDepth:
    """A simulated depth image and where each of its pixels was sampled from.

    Attributes:
        depth_m: ``(H, W) float32`` measured depth (m), ``NaN`` where missing.
        source_rows, source_cols: ``(H, W) int`` pixel of the true image each output pixel
            took its surface from (differs from the pixel itself only where lateral noise
            moved an edge); index any per-pixel label (e.g. a segmentation) with them.
    """

    depth_m: np.ndarray
    source_rows: np.ndarray
    source_cols: np.ndarray


def axial_sigma_from_disparity_m(
    depth_m: np.ndarray, focal_px: float, baseline_m: float, disparity_sigma_px: float
) -> np.ndarray:
    """Depth standard deviation (m) caused by a disparity error: ``z^2 sigma_d / (f B)``."""
    return np.asarray(depth_m) ** 2 * disparity_sigma_px / (focal_px * abs(baseline_m))


def quantisation_step_m(
    depth_m: np.ndarray, focal_px: float, baseline_m: float, disparity_step_px: float
) -> np.ndarray:
    """Depth step (m) between neighbouring disparity levels: ``z^2 step / (f B)``."""
    return axial_sigma_from_disparity_m(depth_m, focal_px, baseline_m, disparity_step_px)


def nguyen_axial_sigma_m(depth_m: np.ndarray, incidence_rad: np.ndarray) -> np.ndarray:
    """Kinect v1 axial standard deviation (m), Nguyen, Izadi & Lovell 2012.

    ``0.0012 + 0.0019 (z - 0.4)^2``, plus ``0.0001 / sqrt(z) theta^2 / (pi/2 - theta)^2`` where
    the incidence angle ``theta`` exceeds 60 deg (clipped at 89 deg).
    """
    z = np.asarray(depth_m, dtype=np.float64)
    theta = np.minimum(np.asarray(incidence_rad, dtype=np.float64), MAX_INCIDENCE_RAD)
    sigma = axial_sigma_m(z)
    grazing = 0.0001 / np.sqrt(z) * theta**2 / (np.pi / 2 - theta) ** 2
    return sigma + np.where(theta > np.deg2rad(60.0), grazing, 0.0)


def nguyen_lateral_sigma_px(incidence_rad: np.ndarray) -> np.ndarray:
    """Kinect v1 lateral standard deviation (px), Nguyen et al. 2012:
    ``0.8 + 0.035 theta / (pi/2 - theta)`` (theta clipped at 89 deg)."""
    theta = np.minimum(np.asarray(incidence_rad, dtype=np.float64), MAX_INCIDENCE_RAD)
    return 0.8 + 0.035 * theta / (np.pi / 2 - theta)


def incidence_angle_rad(depth_m: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Angle (rad) between each pixel's viewing ray and the surface normal there.

    With ``r = ((u - cx) / fx, (v - cy) / fy, 1)`` the pixel's ray and ``z(u, v)`` the depth
    image, the surface normal is ``n = (-fx z_u, -fy z_v, fx z_u r_x + fy z_v r_y + z)`` and
    ``n . r = z``, so ``cos theta = z / (|n| |r|)``. Derivatives are central differences;
    ``NaN`` where the depth or a neighbour is missing.
    """
    z = np.asarray(depth_m, dtype=np.float64)
    height, width = z.shape
    ray_x = ((np.arange(width) - intrinsics.cx) / intrinsics.fx)[None, :]
    ray_y = ((np.arange(height) - intrinsics.cy) / intrinsics.fy)[:, None]
    dz_dv, dz_du = np.gradient(z)
    gx, gy = intrinsics.fx * dz_du, intrinsics.fy * dz_dv
    normal_norm = np.sqrt(gx**2 + gy**2 + (gx * ray_x + gy * ray_y + z) ** 2)
    ray_norm = np.sqrt(ray_x**2 + ray_y**2 + 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.arccos(np.clip(np.abs(z) / (normal_norm * ray_norm), 0.0, 1.0))


def disparity_px(depth_m: np.ndarray, focal_px: float, baseline_m: float) -> np.ndarray:
    """Disparity ``f |B| / z`` (px); 0 (a surface at infinity) where depth is missing."""
    with np.errstate(divide="ignore", invalid="ignore"):
        disparity = focal_px * abs(baseline_m) / np.asarray(depth_m, dtype=np.float64)
    return np.nan_to_num(disparity, nan=0.0, posinf=0.0)


def shadow_mask(depth_m: np.ndarray, focal_px: float, baseline_m: float) -> np.ndarray:
    """Pixels the second viewpoint (projector or right camera) cannot see.

    The second viewpoint sits at ``baseline_m`` along the camera x axis. A surface point at
    column ``u`` projects to column ``u - f B / z`` there; scanning each row away from the
    second viewpoint, a pixel is hidden when a pixel on the near side of it already reaches
    as far in the second view (its ray is blocked by a closer surface). Returns ``(H, W)``
    bool; missing depth is never a shadow (and never casts one).
    """
    flip = baseline_m < 0
    depth = np.asarray(depth_m, dtype=np.float64)
    depth = depth[:, ::-1] if flip else depth
    seen = np.isfinite(depth)
    column_second = np.arange(depth.shape[1], dtype=np.float64)[None, :] - disparity_px(
        depth, focal_px, baseline_m
    )
    column_second[~seen] = np.inf
    reach_from_right = np.minimum.accumulate(column_second[:, ::-1], axis=1)[:, ::-1]
    nearest_on_right = np.full_like(column_second, np.inf)
    nearest_on_right[:, :-1] = reach_from_right[:, 1:]
    hidden = seen & (column_second > nearest_on_right)
    return hidden[:, ::-1] if flip else hidden


def _jumps(disparity: np.ndarray, jump_px: float) -> np.ndarray:
    """Pixels with a 4-neighbour whose disparity differs by more than ``jump_px``."""
    jump = np.zeros(disparity.shape, dtype=bool)
    vertical = np.abs(np.diff(disparity, axis=0)) > jump_px
    horizontal = np.abs(np.diff(disparity, axis=1)) > jump_px
    jump[:-1, :] |= vertical
    jump[1:, :] |= vertical
    jump[:, :-1] |= horizontal
    jump[:, 1:] |= horizontal
    return jump


def discontinuity_mask(
    depth_m: np.ndarray, focal_px: float, baseline_m: float, jump_px: float, margin_px: int
) -> np.ndarray:
    """Pixels within ``margin_px`` of a disparity jump larger than ``jump_px`` between
    4-neighbours (missing depth counts as disparity 0, so silhouettes are edges)."""
    if margin_px <= 0:
        return np.zeros(np.shape(depth_m), dtype=bool)
    jump = _jumps(disparity_px(depth_m, focal_px, baseline_m), jump_px)
    if margin_px > 1:
        from scipy import ndimage  # here, so the sensor plugins import quickly

        jump = ndimage.binary_dilation(jump, iterations=margin_px - 1)
    return jump & np.isfinite(depth_m)


def pixel_grid(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, cols)`` index images of an image of ``shape`` (int64)."""
    rows = np.repeat(np.arange(shape[0], dtype=np.int64)[:, None], shape[1], axis=1)
    cols = np.repeat(np.arange(shape[1], dtype=np.int64)[None, :], shape[0], axis=0)
    return rows, cols


def move_edges_laterally(
    depth_m: np.ndarray,
    sigma_px: np.ndarray,
    focal_px: float,
    baseline_m: float,
    jump_px: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lateral noise: each pixel looks up a neighbour ``N(0, sigma_px)`` pixels away and takes
    its surface only if that neighbour lies across a depth discontinuity.

    Within a smooth surface the pixel keeps its own depth (the axial sigma already holds the
    error measured on tilted planes), so the noise shows where it does on a real sensor: as
    ragged, displaced silhouettes. Offsets are drawn only for pixels within 4 sigma of a
    discontinuity (the others could not reach one). Returns
    ``(depth_m, source_rows, source_cols)``.
    """
    height, width = depth_m.shape
    rows, cols = pixel_grid(depth_m.shape)
    sigma = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), depth_m.shape)
    disparity = disparity_px(depth_m, focal_px, baseline_m)
    reach_px = int(np.ceil(4.0 * sigma.max()))
    jumps = _jumps(disparity, jump_px).astype(np.uint8)
    from scipy import ndimage

    near_edge = ndimage.maximum_filter(jumps, size=2 * reach_px + 1) > 0
    flat = np.flatnonzero(near_edge)
    offsets = rng.standard_normal((2, flat.size)) * sigma.reshape(-1)[flat]
    near_rows, near_cols = rows.reshape(-1)[flat], cols.reshape(-1)[flat]
    source_rows = np.clip(np.rint(near_rows + offsets[0]).astype(np.int64), 0, height - 1)
    source_cols = np.clip(np.rint(near_cols + offsets[1]).astype(np.int64), 0, width - 1)
    across_edge = (
        np.abs(disparity[source_rows, source_cols] - disparity[near_rows, near_cols]) > jump_px
    )
    rows.reshape(-1)[flat[across_edge]] = source_rows[across_edge]
    cols.reshape(-1)[flat[across_edge]] = source_cols[across_edge]
    return depth_m[rows, cols], rows, cols


def quantised_disparity_depth(
    depth_m: np.ndarray,
    disparity_sigma_px: np.ndarray | float,
    focal_px: float,
    baseline_m: float,
    disparity_step_px: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Add disparity noise of total standard deviation ``disparity_sigma_px`` (quantisation
    included) and round the disparity to ``disparity_step_px``; return depth (m)."""
    focal_baseline = focal_px * abs(baseline_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        disparity = focal_baseline / np.asarray(depth_m, dtype=np.float64)
    variance = np.asarray(disparity_sigma_px, dtype=np.float64) ** 2 - disparity_step_px**2 / 12
    noise_sigma = np.sqrt(np.maximum(variance, 0.0))
    disparity = disparity + rng.standard_normal(disparity.shape) * noise_sigma
    if disparity_step_px > 0:
        disparity = np.rint(disparity / disparity_step_px) * disparity_step_px
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = focal_baseline / disparity
    return np.where(disparity > 0, depth, np.nan)


def kinect_v1_dropouts(
    depth_m: np.ndarray, intrinsics: CameraIntrinsics, noise: KinectV1Noise | None = None
) -> np.ndarray:
    """``(H, W)`` bool: the pixels of a scene with true depth ``depth_m`` for which a Kinect
    v1 returns nothing, the edges taken where they are (no lateral jitter): projector
    shadows, pixels within ``edge_margin_px`` of a depth discontinuity (the object's outline
    against what lies behind it, on both sides), surfaces beyond ``max_incidence_deg`` and
    depths outside the range. :func:`simulate_kinect_v1` drops the same pixels after it has
    jittered the edges."""
    noise = noise or KinectV1Noise()
    depth = np.asarray(depth_m, dtype=np.float64)
    focal = intrinsics.fx
    incidence = np.nan_to_num(incidence_angle_rad(depth, intrinsics), nan=0.0)
    missing = discontinuity_mask(
        depth, focal, noise.baseline_m, noise.edge_jump_px, noise.edge_margin_px
    )
    if noise.shadows:
        missing |= shadow_mask(depth, focal, noise.baseline_m)
    missing |= incidence > np.deg2rad(noise.max_incidence_deg)
    with np.errstate(invalid="ignore"):
        missing |= ~((depth >= noise.min_range_m) & (depth <= noise.max_range_m))
    return missing


def simulate_kinect_v1(
    depth_m: np.ndarray,
    intrinsics: CameraIntrinsics,
    rng: np.random.Generator,
    noise: KinectV1Noise | None = None,
) -> SimulatedDepth:
    """What a Kinect v1 reports for a scene whose true depth image is ``depth_m``.

    Steps: projector shadows (on the true geometry); lateral edge jitter sigma_L(theta);
    missing pixels at depth discontinuities and at grazing incidence; disparity noise
    (sigma_z of the chosen axial model converted to disparity) and 1/8-px disparity
    rounding; missing outside the range.
    The noise is independent per pixel (the sensor's 9x9 correlation window, which makes real
    Kinect noise spatially correlated, is not modelled).
    """
    noise = noise or KinectV1Noise()
    focal = intrinsics.fx
    depth_true = np.asarray(depth_m, dtype=np.float64)
    rows, cols = pixel_grid(depth_true.shape)
    incidence = np.nan_to_num(incidence_angle_rad(depth_true, intrinsics), nan=0.0)
    missing = (
        shadow_mask(depth_true, focal, noise.baseline_m)
        if noise.shadows
        else np.zeros(depth_true.shape, bool)
    )
    depth = depth_true
    if noise.lateral_noise:
        depth, rows, cols = move_edges_laterally(
            depth_true,
            nguyen_lateral_sigma_px(incidence),
            focal,
            noise.baseline_m,
            noise.edge_jump_px,
            rng,
        )
        missing = missing[rows, cols]
        incidence = incidence[rows, cols]
    missing |= discontinuity_mask(
        depth, focal, noise.baseline_m, noise.edge_jump_px, noise.edge_margin_px
    )
    missing |= incidence > np.deg2rad(noise.max_incidence_deg)
    if not noise.axial_noise:
        sigma_px: np.ndarray | float = 0.0
    elif noise.axial_model == "nguyen":
        sigma_px = nguyen_axial_sigma_m(depth, incidence) * focal * noise.baseline_m / depth**2
    else:
        sigma_px = noise.disparity_sigma_px
    measured = quantised_disparity_depth(
        depth, sigma_px, focal, noise.baseline_m, noise.disparity_step_px, rng
    )
    missing |= ~((measured >= noise.min_range_m) & (measured <= noise.max_range_m))
    measured = np.where(missing, np.nan, measured)
    return SimulatedDepth(measured.astype(np.float32), rows, cols)


def simulate_stereo(
    depth_m: np.ndarray,
    intrinsics: CameraIntrinsics,
    rng: np.random.Generator,
    noise: StereoNoise | None = None,
) -> SimulatedDepth:
    """What a rectified stereo pair reports, in the left camera, for true depth ``depth_m``.

    Steps: left-right occlusions (surfaces the right camera cannot see); missing pixels at
    depth discontinuities (the matching window straddles them); Gaussian disparity noise and
    sub-pixel rounding, ``sigma_z = z^2 sigma_d / (f B)``; missing outside the disparity
    search range. Low-texture matching failures are not modelled.
    """
    noise = noise or StereoNoise()
    focal = intrinsics.fx
    depth_true = np.asarray(depth_m, dtype=np.float64)
    rows, cols = pixel_grid(depth_true.shape)
    missing = discontinuity_mask(
        depth_true, focal, noise.baseline_m, noise.edge_jump_px, noise.edge_margin_px
    )
    if noise.occlusions:
        missing |= shadow_mask(depth_true, focal, noise.baseline_m)
    sigma_px = noise.disparity_sigma_px if noise.axial_noise else 0.0
    measured = quantised_disparity_depth(
        depth_true, sigma_px, focal, noise.baseline_m, noise.disparity_step_px, rng
    )
    missing |= ~((measured >= noise.min_range_m) & (measured <= noise.max_range_m))
    measured = np.where(missing, np.nan, measured)
    return SimulatedDepth(measured.astype(np.float32), rows, cols)
