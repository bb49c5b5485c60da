"""Pinhole camera rendering in PyBullet: pose from a viewpoint, OpenGL matrices from
intrinsics, and metric depth, colour and segmentation from ``getCameraImage``.

Frames: the robot frame ``R`` is PyBullet's world frame. Camera poses are returned in the
OpenCV optical convention (x right, y down, z along the optical axis) as ``T_robot_camera``;
the OpenGL eye frame PyBullet renders with (x right, y up, z backward) is used only inside
this module.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import pybullet

from pipeline.errors import ConfigError
from pipeline.geometry.poses import look_at, rotation_z
from pipeline.params import check_ordered, param
from pipeline.sim.depth_noise import SimulatedDepth
from pipeline.sim.kinect import KINECT_V1_INTRINSICS as KINECT
from pipeline.stages import SensorSource
from pipeline.types import CameraIntrinsics, DepthObservation

if TYPE_CHECKING:
    from pipeline.stages import World

#: OpenCV optical frame -> OpenGL eye frame (flip y and z).
T_CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
#: Where TinyRenderer samples pixel (column i, row j) relative to the pixel's centre, in
#: pixels (column, row): at a corner, not the centre (measured on a tilted plane; see
#: tests/test_camera_render.py). :func:`projection_matrix` moves the principal point by it,
#: so each pixel shows the surface on its centre's ray.
TINY_RENDERER_SAMPLE_OFFSET_PX = (-0.5, 0.5)


@dataclass(frozen=True)
class Rendering:
    """One noise-free rendered image.

    Attributes:
        rgb: ``(H, W, 3) uint8`` colour image.
        depth_m: ``(H, W) float32`` true depth along the optical axis (m), ``NaN`` where no
            body was hit within the far plane.
        segmentation: ``(H, W) int32`` PyBullet body id seen at each pixel, ``-1`` for none.
        T_robot_camera: the true camera pose (OpenCV optical frame), ``(4, 4)``.
    """

    rgb: np.ndarray
    depth_m: np.ndarray
    segmentation: np.ndarray
    T_robot_camera: np.ndarray


def view_matrix(T_robot_camera: np.ndarray) -> list[float]:
    """PyBullet's view matrix (column-major, 16 floats) for an OpenCV camera pose."""
    T_gl_robot = T_CV_TO_GL @ np.linalg.inv(T_robot_camera)
    return T_gl_robot.flatten(order="F").tolist()


def projection_matrix(intrinsics: CameraIntrinsics, near_m: float, far_m: float) -> list[float]:
    """OpenGL projection (column-major, 16 floats) reproducing the pinhole ``intrinsics``.

    Maps eye coordinates so that pixel centres land at ``u = fx X/Z + cx``,
    ``v = fy Y/Z + cy`` (OpenCV convention: ``(0, 0)`` is the centre of the top-left pixel,
    rows down), with the normalised-device range ``[-1, 1]`` spanning the image's outer edges,
    corrected for TinyRenderer sampling pixels at a corner
    (:data:`TINY_RENDERER_SAMPLE_OFFSET_PX`).
    """
    width, height = intrinsics.width, intrinsics.height
    projection = np.zeros((4, 4))
    projection[0, 0] = 2.0 * intrinsics.fx / width
    column_shift, row_shift = TINY_RENDERER_SAMPLE_OFFSET_PX
    projection[0, 2] = 1.0 - 2.0 * (intrinsics.cx + 0.5 + column_shift) / width
    projection[1, 1] = 2.0 * intrinsics.fy / height
    projection[1, 2] = 2.0 * (intrinsics.cy + 0.5 + row_shift) / height - 1.0
    projection[2, 2] = -(far_m + near_m) / (far_m - near_m)
    projection[2, 3] = -2.0 * far_m * near_m / (far_m - near_m)
    projection[3, 2] = -1.0
    return projection.flatten(order="F").tolist()


def metric_depth(depth_buffer: np.ndarray, near_m: float, far_m: float) -> np.ndarray:
    """Depth along the optical axis (m) from OpenGL depth-buffer values in ``[0, 1]``:
    ``z = far near / (far - (far - near) d)``; ``NaN`` at the far plane (nothing hit)."""
    buffer = np.asarray(depth_buffer, dtype=np.float64)
    depth = far_m * near_m / (far_m - (far_m - near_m) * buffer)
    return np.where(buffer < 1.0, depth, np.nan)


def render(
    client: int,
    intrinsics: CameraIntrinsics,
    T_robot_camera: np.ndarray,
    near_m: float = 0.05,
    far_m: float = 6.0,
) -> Rendering:
    """Render colour, metric depth and body segmentation with PyBullet's TinyRenderer.

    Works in DIRECT mode (no GPU); shadows off, default light from above the camera.
    """
    _, _, rgba, depth_buffer, segmentation = pybullet.getCameraImage(
        intrinsics.width,
        intrinsics.height,
        viewMatrix=view_matrix(T_robot_camera),
        projectionMatrix=projection_matrix(intrinsics, near_m, far_m),
        renderer=pybullet.ER_TINY_RENDERER,
        shadow=0,
        physicsClientId=client,
    )
    shape = (intrinsics.height, intrinsics.width)
    rgb = np.asarray(rgba, dtype=np.uint8).reshape(*shape, 4)[..., :3].copy()
    depth_m = metric_depth(np.asarray(depth_buffer).reshape(shape), near_m, far_m)
    segmentation = np.asarray(segmentation, dtype=np.int32).reshape(shape)
    depth_m[segmentation < 0] = np.nan
    return Rendering(rgb, depth_m.astype(np.float32), segmentation, np.array(T_robot_camera))


def calibration_error(
    T_robot_camera: np.ndarray, yaw_rad: float, translation_m: np.ndarray, pivot_robot: np.ndarray
) -> np.ndarray:
    """The camera pose a miscalibrated system believes in.

    The error is a rotation by ``yaw_rad`` about the vertical axis through ``pivot_robot``
    followed by a translation ``translation_m`` (frame ``R``): a cloud reconstructed with
    the believed pose is the true cloud moved by exactly that planar motion (the form of the
    estimator's bias), and a yaw error alone does not shift points at the pivot.
    """
    rotation = rotation_z(yaw_rad)
    pivot = np.asarray(pivot_robot, dtype=np.float64)
    T_believed_true = np.eye(4)
    T_believed_true[:3, :3] = rotation
    T_believed_true[:3, 3] = pivot - rotation @ pivot + np.asarray(translation_m, dtype=np.float64)
    return T_believed_true @ T_robot_camera


@dataclass(frozen=True)
class CameraParams:
    """Viewpoint, image and calibration-error parameters shared by the simulated sensors."""

    distance_m: float = param(1.0, "distance from the camera to the look-at target (m)", above=0.0)
    elevation_deg: float = param(45.0, "camera elevation above the table plane (deg)")
    azimuth_deg: float = param(180.0, "camera azimuth about +z from the robot's +x axis (deg)")
    target_m: tuple[float, ...] = param(
        (0.0, 0.0, 0.05), "look-at point (x, y, z) in frame R (m); see target_relative_to"
    )
    target_relative_to: Literal["object", "robot"] = param(
        "object",
        "'object': target_m is an offset from the object's base position; 'robot': absolute",
    )
    width: int = param(KINECT.width, "image width (px)", at_least=1)
    height: int = param(KINECT.height, "image height (px)", at_least=1)
    fx: float = param(KINECT.fx, "focal length along x (px)", above=0.0)
    fy: float = param(KINECT.fy, "focal length along y (px)", above=0.0)
    cx: float = param(KINECT.cx, "principal point column, from the top-left pixel centre (px)")
    cy: float = param(KINECT.cy, "principal point row, from the top-left pixel centre (px)")
    near_m: float = param(0.05, "renderer near clipping plane (m)", above=0.0)
    far_m: float = param(
        6.0, "renderer far clipping plane (m); nothing is seen beyond it", above=0.0
    )
    noise: bool = param(True, "apply the sensor's noise and missing-data model")
    calibration_yaw_deg: float = param(
        0.0, "calibration error: yaw of the believed camera pose about the target's vertical (deg)"
    )
    calibration_translation_m: tuple[float, ...] = param(
        (0.0, 0.0, 0.0), "calibration error: translation (x, y, z) of the believed pose in R (m)"
    )

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The camera's pinhole intrinsics."""
        return CameraIntrinsics(self.width, self.height, self.fx, self.fy, self.cx, self.cy)


def check_camera_params(params: CameraParams, section: str) -> None:
    """What the declared bounds of :class:`CameraParams` cannot say: three values in each
    position, and ``near_m < far_m``. ``section`` is the sensor's config section (its
    messages name the full key).

    Raises:
        ConfigError: naming the key.
    """
    for key in ("target_m", "calibration_translation_m"):
        values = getattr(params, key)
        if len(values) != 3:
            raise ConfigError(
                f"config key '{section}.{key}': expected 3 values (x, y, z), got {len(values)}"
            )
    check_ordered(params, section, "near_m", "far_m")


def check_depth_range(params: Any, section: str) -> None:
    """A triangulating sensor's depth range (``min_range_m``, ``max_range_m``) must be a
    range that overlaps the renderer's (``near_m``, ``far_m``), or no pixel could ever have
    a depth; and its ``baseline_m`` must not be 0 (depth is ``f B / disparity``; a negative
    baseline puts the second viewpoint on the camera's left).

    Raises:
        ConfigError: naming the key.
    """
    check_ordered(params, section, "min_range_m", "max_range_m")
    check_ordered(params, section, "min_range_m", "far_m", "nothing is rendered beyond it")
    check_ordered(params, section, "near_m", "max_range_m", "nothing is rendered before near_m")
    if params.baseline_m == 0.0:
        raise ConfigError(
            f"config key '{section}.baseline_m': must not be 0 (depth is f B / disparity; "
            "a negative baseline puts the second viewpoint on the camera's left)"
        )


def observe(
    world: World,
    params: CameraParams,
    corrupt: Callable[[np.ndarray, CameraIntrinsics, np.random.Generator], SimulatedDepth],
    again: DepthObservation | None = None,
) -> DepthObservation:
    """Render ``world`` from the viewpoint in ``params`` and pass the true depth through the
    sensor model ``corrupt`` (skipped when ``params.noise`` is False). With ``again`` (an
    earlier observation of this sensor) the camera stays where it took that one, with the
    same calibration error, however the object has moved since.

    Uses only the :class:`~pipeline.stages.World` contract (``render``, ``object_pose``,
    ``table_height_m``, ``rng``), so it works in any world. The observation carries the
    *believed* camera pose (with the calibration error), the table height and the
    ground-truth object mask registered to the returned depth image.
    """
    target_robot = np.array(params.target_m, dtype=np.float64)
    if params.target_relative_to == "object":
        target_robot = target_robot + world.object_pose().position_m
    T_robot_camera = look_at(
        target_robot,
        params.distance_m,
        np.deg2rad(params.elevation_deg),
        np.deg2rad(params.azimuth_deg),
    )
    if again is not None:
        error = np.eye(4) if again.calibration_error is None else again.calibration_error
        T_robot_camera = np.linalg.inv(error) @ again.T_robot_camera
    intrinsics = params.intrinsics
    image = world.render(intrinsics, T_robot_camera, params.near_m, params.far_m)
    object_mask = image.object_mask
    depth_m = image.depth_m
    if params.noise:
        simulated = corrupt(depth_m, intrinsics, world.rng)
        depth_m = simulated.depth_m
        object_mask = object_mask[simulated.source_rows, simulated.source_cols]
    T_believed = calibration_error(
        T_robot_camera,
        np.deg2rad(params.calibration_yaw_deg),
        np.array(params.calibration_translation_m),
        target_robot,
    )
    if again is not None:
        T_believed = again.T_robot_camera
    return DepthObservation(
        depth_m=depth_m,
        rgb=image.rgb,
        intrinsics=intrinsics,
        T_robot_camera=T_believed,
        table_height_m=float(world.table_height_m),
        object_mask=object_mask,
        calibration_error=T_believed @ np.linalg.inv(T_robot_camera),
    )


class SimulatedCamera(SensorSource):
    """A sensor that renders the world from its :class:`CameraParams` viewpoint and passes
    the depth through a noise model (:func:`observe`): a subclass gives the model
    (:meth:`corrupt`), its ``Params`` the camera's and the depth range's fields, which are
    checked together (:func:`check_camera_params`, :func:`check_depth_range`)."""

    @classmethod
    def check_params(cls, params: Any) -> None:
        super().check_params(params)
        check_camera_params(params, f"sensor.{cls.name}")
        check_depth_range(params, f"sensor.{cls.name}")

    @abstractmethod
    def corrupt(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> SimulatedDepth:
        """The sensor's depth from the true ``depth_m`` (m), drawing noise from ``rng``."""

    def observe(self, world: World) -> DepthObservation:
        return observe(world, self.params, self.corrupt)

    def observe_again(self, world: World, first: DepthObservation) -> DepthObservation:
        return observe(world, self.params, self.corrupt, again=first)
