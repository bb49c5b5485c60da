"""Simulation kernels the built-in sensors and tactile model are made of: camera
rendering, depth-noise models, the shipped hands; and the simulated worlds themselves
(``Pybullet``, ``Mujoco``), for a world plugin that subclasses one to offer a hand of its
own (``extra_hands``, docs/hands.md). Importing a world class does not import its
simulator: that happens when a scene is loaded.

What is named here keeps its meaning across releases, as :mod:`pipeline.api` does.
Each name loads its module when it is first imported, so a plugin pays only for the
kernels it uses (``symfuse plugins`` imports every plugin and must stay quick).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipeline.api._lazy import lazy_attributes

if TYPE_CHECKING:
    from pipeline.shipped_hands import ShippedHandsWorld
    from pipeline.sim.camera import (
        CameraParams,
        SimulatedCamera,
        check_camera_params,
        check_depth_range,
        observe,
    )
    from pipeline.sim.depth_noise import (
        KinectV1Noise,
        SimulatedDepth,
        StereoNoise,
        simulate_kinect_v1,
        simulate_stereo,
    )
    from plugins.worlds.mujoco_world import Mujoco
    from plugins.worlds.pybullet_world import Pybullet

#: Where each name comes from: (module, name there).
_SOURCES = {
    "CameraParams": ("pipeline.sim.camera", "CameraParams"),
    "KinectV1Noise": ("pipeline.sim.depth_noise", "KinectV1Noise"),
    "Mujoco": ("plugins.worlds.mujoco_world", "Mujoco"),
    "Pybullet": ("plugins.worlds.pybullet_world", "Pybullet"),
    "ShippedHandsWorld": ("pipeline.shipped_hands", "ShippedHandsWorld"),
    "SimulatedCamera": ("pipeline.sim.camera", "SimulatedCamera"),
    "SimulatedDepth": ("pipeline.sim.depth_noise", "SimulatedDepth"),
    "StereoNoise": ("pipeline.sim.depth_noise", "StereoNoise"),
    "check_camera_params": ("pipeline.sim.camera", "check_camera_params"),
    "check_depth_range": ("pipeline.sim.camera", "check_depth_range"),
    "observe": ("pipeline.sim.camera", "observe"),
    "simulate_kinect_v1": ("pipeline.sim.depth_noise", "simulate_kinect_v1"),
    "simulate_stereo": ("pipeline.sim.depth_noise", "simulate_stereo"),
}

__all__ = [
    "CameraParams",
    "KinectV1Noise",
    "Mujoco",
    "Pybullet",
    "ShippedHandsWorld",
    "SimulatedCamera",
    "SimulatedDepth",
    "StereoNoise",
    "check_camera_params",
    "check_depth_range",
    "observe",
    "simulate_kinect_v1",
    "simulate_stereo",
]


__getattr__ = lazy_attributes(__name__, globals(), _SOURCES)
