"""Sensor source ``recorded``: a depth view read from a file or a ROS bag instead of a world."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.api import (
    ConfigError,
    DepthObservation,
    InputError,
    SensorSource,
    World,
    backproject_depth,
    hookimpl,
    param,
)
from pipeline.api.io import Capture, read_capture
from pipeline.api.perception import fit_support_plane, frame_on_plane


class Recorded(SensorSource):
    """A recorded capture: organised PCD, depth PNG/NPY + camera.json, or a ROS 1/2 bag.

    Reads ``path`` (see :mod:`pipeline.io.captures` and :mod:`pipeline.io.bags`) and ignores the
    world. When the recording has no robot frame (no ``T_robot_camera`` in camera.json, no
    /tf in the bag) the frame is built on the support plane: among the scene's dominant
    planes (open3d RANSAC), the one below the camera with something standing on it,
    facing up in the image where one does (a table, not the wall behind it; see
    :func:`~pipeline.perception.support.fit_support_plane`), z up along its normal, x
    along the optical axis projected on it, table height 0. Without a colour image,
    ``rgb`` holds the depth in grey levels.
    """

    name = "recorded"

    @dataclass(frozen=True)
    class Params:
        path: str = param("", "the capture: .pcd, .png/.npy depth image, .bag or ROS 2 bag folder")
        camera: str = param("", "camera.json of a depth image ('' = camera.json beside it)")
        colour: str = param("", "colour PNG of a depth image ('' = rgb.png beside it, if any)")
        topic: str = param("", "bag topic: PointCloud2 or Image ('' = the first that fits)")
        robot_frame: str = param("", "bag: tf frame to express the scene in ('' = tf root)")
        plane_inlier_m: float = param(
            0.01, "support plane: largest distance of an inlier (m)", above=0.0
        )
        plane_iterations: int = param(1000, "support plane: RANSAC iterations", at_least=1)
        plane_voxel_m: float = param(
            0.01, "support plane: voxel grid RANSAC runs on (m; 0 = every point)", at_least=0.0
        )
        plane_seed: int = param(0, "support plane: RANSAC seed")
        min_plane_fraction: float = param(
            0.1,
            "support plane: least fraction of the valid pixels (and of the voxels) on it",
            above=0.0,
            at_most=1.0,
        )

    def read(self) -> Capture:
        """The capture the parameters name."""
        p = self.params
        if not p.path:
            raise ConfigError("sensor.recorded.path: no capture given (symfuse complete SCAN)")
        return read_capture(
            Path(p.path),
            camera=Path(p.camera) if p.camera else None,
            colour=Path(p.colour) if p.colour else None,
            topic=p.topic,
            robot_frame=p.robot_frame,
        )

    def support_frame(self, capture: Capture) -> np.ndarray:
        """``T_robot_camera`` of the frame standing on the capture's support plane."""
        p = self.params
        points, _ = backproject_depth(capture.depth_m, capture.intrinsics, np.eye(4))
        try:
            plane = fit_support_plane(
                points,
                inlier_distance_m=p.plane_inlier_m,
                iterations=p.plane_iterations,
                voxel_m=p.plane_voxel_m,
                seed=p.plane_seed,
                min_fraction=p.min_plane_fraction,
            )
        except ValueError as exc:
            raise InputError(f"{capture.source}: no support plane: {exc}") from None
        fraction = plane.inliers / len(points)
        if fraction < p.min_plane_fraction:
            raise InputError(
                f"{capture.source}: no support plane: the dominant plane holds {fraction:.1%} "
                f"of the points (sensor.recorded.min_plane_fraction = "
                f"{p.min_plane_fraction:.0%})"
            )
        return frame_on_plane(plane)

    def observe(self, world: World | None = None) -> DepthObservation:
        capture = self.read()
        given = capture.T_robot_camera is not None
        T_robot_camera = capture.T_robot_camera if given else self.support_frame(capture)
        return capture.view(
            T_robot_camera, capture.table_height_m if given else 0.0, frame_from_support=not given
        )


@hookimpl
def symfuse_register_stages(registry):
    registry.add(Recorded)
