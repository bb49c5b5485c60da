"""Built-in sensor source ``pybullet-stereo``: a simulated narrow-angle stereo pair."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.api import (
    CameraIntrinsics,
    hookimpl,
    param,
    project,
)
from pipeline.api.sim import (
    CameraParams,
    SimulatedCamera,
    SimulatedDepth,
    StereoNoise,
    simulate_stereo,
)


class PybulletStereo(SimulatedCamera):
    """Stereo depth + colour (z^2 sigma_d / (f B) noise, occlusions, edges), any world.

    Models the narrow-angle camera pair of an Armar III-like head: 640x480 images, a 90 mm
    baseline and a 12 mm lens on 7.4 um pixels (f about 1600 px, 22 deg horizontal field
    of view) -- the lens and pixel figures are unconfirmed estimates; all are parameters.
    Depth is registered to the left camera. Matching failures on untextured surfaces are
    not modelled. Works in any world (it asks the world for a noise-free rendering).
    """

    name = "pybullet-stereo"

    @dataclass(frozen=True)
    class Params(CameraParams):
        fx: float = param(1600.0, "focal length along x (px)", above=0.0)
        fy: float = param(1600.0, "focal length along y (px)", above=0.0)
        cx: float = param(319.5, "principal point column, from the top-left pixel centre (px)")
        cy: float = param(239.5, "principal point row, from the top-left pixel centre (px)")
        baseline_m: float = param(0.09, "distance to the right camera along image x (m)")
        disparity_sigma_px: float = param(0.2, "disparity noise of the matcher (px)", at_least=0.0)
        disparity_step_px: float = param(0.0625, "sub-pixel disparity step (px; 1/16)", above=0.0)
        min_range_m: float = param(
            0.3, "nearest depth the disparity search covers (m)", at_least=0.0
        )
        max_range_m: float = param(3.0, "farthest depth the disparity search covers (m)", above=0.0)
        axial_noise: bool = param(True, "add disparity noise; off leaves quantisation")
        occlusions: bool = param(True, "drop pixels the right camera cannot see")
        edge_jump_px: float = param(
            1.0, "disparity jump that counts as a depth edge (px)", above=0.0
        )
        edge_margin_px: int = param(
            2, "pixels dropped on each side of a depth edge (px)", at_least=0
        )

    def corrupt(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> SimulatedDepth:
        return simulate_stereo(depth_m, intrinsics, rng, project(StereoNoise, self.params))


@hookimpl
def symfuse_register_stages(registry):
    registry.add(PybulletStereo)
