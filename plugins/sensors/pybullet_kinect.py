"""Built-in sensor source ``pybullet-kinect``: a simulated Kinect v1 in a PyBullet world."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from pipeline.api import (
    CameraIntrinsics,
    hookimpl,
    param,
    project,
)
from pipeline.api.sim import (
    CameraParams,
    KinectV1Noise,
    SimulatedCamera,
    SimulatedDepth,
    simulate_kinect_v1,
)


class PybulletKinect(SimulatedCamera):
    """Kinect v1 depth + colour (Nguyen 2012 noise, 1/8-px disparity, shadows), any world.

    Asks the world for a noise-free rendering (PyBullet: TinyRenderer) at the Kinect's
    640x480 intrinsics (575.8 px, principal point (314.5, 235.5)) from a viewpoint given by
    distance, elevation and azimuth toward a target, then applies
    :func:`pipeline.sim.depth_noise.simulate_kinect_v1` with ``world.rng``.
    """

    name = "pybullet-kinect"

    @dataclass(frozen=True)
    class Params(CameraParams):
        baseline_m: float = param(0.075, "projector-camera baseline along image x (m)")
        disparity_step_px: float = param(0.125, "disparity quantisation step (px; 1/8)", above=0.0)
        min_range_m: float = param(0.5, "nearest depth the sensor returns (m)", at_least=0.0)
        max_range_m: float = param(4.0, "farthest depth the sensor returns (m)", above=0.0)
        axial_model: Literal["nguyen", "khoshelham"] = param(
            "nguyen",
            "axial noise: 'nguyen' sigma(z, angle) (Nguyen 2012) or 'khoshelham' z^2 law (2012)",
        )
        disparity_sigma_px: float = param(
            0.0625, "disparity noise of the 'khoshelham' model (px; 0.5 of 1/8 px)", at_least=0.0
        )
        axial_noise: bool = param(True, "add axial (disparity) noise; off leaves quantisation")
        lateral_noise: bool = param(True, "jitter depth edges laterally (Nguyen 2012 sigma_L)")
        shadows: bool = param(True, "drop pixels in the projector's shadow")
        max_incidence_deg: float = param(
            80.0,
            "surfaces seen more obliquely than this (ray vs normal) return nothing (deg)",
            above=0.0,
            at_most=90.0,
        )
        edge_jump_px: float = param(
            1.0, "disparity jump that counts as a depth edge (px)", above=0.0
        )
        edge_margin_px: int = param(
            1, "pixels dropped on each side of a depth edge (px)", at_least=0
        )

    def corrupt(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> SimulatedDepth:
        return simulate_kinect_v1(depth_m, intrinsics, rng, project(KinectV1Noise, self.params))


@hookimpl
def symfuse_register_stages(registry):
    registry.add(PybulletKinect)
