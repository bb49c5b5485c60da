"""``camera.json``: the camera a depth image was taken with.

Intrinsics in pixels, the believed ``T_robot_camera`` (OpenCV optical frame: x right, y
down, z forward; metres) and the table height in the robot frame when known. The reader
validates what it reads and raises :class:`~pipeline.errors.InputError` with a one-line
message naming the file and the key at fault.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import InputError
from pipeline.io.formats import check_keys, read_json, require_file, rigid_transform
from pipeline.io.units import UNITS_IN_METRES, check_distance
from pipeline.types import CameraIntrinsics, DepthObservation


@dataclass(frozen=True)
class CameraFile:
    """What a ``camera.json`` holds: intrinsics, the camera pose in the robot frame (None
    when the recording has no robot frame) and the table height in that frame, if known."""

    intrinsics: CameraIntrinsics
    T_robot_camera: np.ndarray | None
    table_height_m: float | None


def camera_to_json(observation: DepthObservation) -> dict[str, Any]:
    """Intrinsics (px) and the believed camera pose ``T_robot_camera`` (OpenCV frame)."""
    k = observation.intrinsics
    return {
        "intrinsics": {
            "width": k.width,
            "height": k.height,
            "fx": k.fx,
            "fy": k.fy,
            "cx": k.cx,
            "cy": k.cy,
        },
        "T_robot_camera": np.asarray(observation.T_robot_camera).tolist(),
        "frame": "opencv optical frame (x right, y down, z forward), metres",
        "table_height_m": observation.table_height_m,
    }


def _positive(value: Any, where: str, path: Path) -> float:
    if not isinstance(value, int | float) or isinstance(value, bool) or not 0 < value < math.inf:
        raise InputError(f"{path}: {where} must be a positive finite number, got {value!r}")
    return float(value)


#: The keys of a ``camera.json`` (:func:`camera_to_json`) and of its ``intrinsics``.
CAMERA_KEYS = ("intrinsics", "T_robot_camera", "frame", "table_height_m")
INTRINSICS_KEYS = ("width", "height", "fx", "fy", "cx", "cy")


def read_camera(path: Path) -> CameraFile:
    """Read a ``camera.json`` as :func:`camera_to_json` writes it.

    ``T_robot_camera`` and ``table_height_m`` may be missing or null (a camera with
    intrinsics only); ``cx``, ``cy`` may be any finite number.
    """
    path = require_file(path)
    document = read_json(path)
    k = document.get("intrinsics") if isinstance(document, dict) else None
    if not isinstance(k, dict):
        raise InputError(f"{path}: 'intrinsics' must be an object with width, height, fx, ...")
    # A misspelt key would silently drop the camera pose (and build a frame on the table).
    check_keys(document, CAMERA_KEYS, "", path)
    check_keys(k, INTRINSICS_KEYS, "intrinsics.", path)
    size = []
    for key in ("width", "height"):
        if not isinstance(k.get(key), int) or isinstance(k.get(key), bool) or k[key] < 1:
            raise InputError(f"{path}: intrinsics.{key} must be a positive integer")
        size.append(k[key])
    focal = [_positive(k.get(key), f"intrinsics.{key}", path) for key in ("fx", "fy")]
    centre = []
    for key in ("cx", "cy"):
        value = k.get(key)
        if (
            not isinstance(value, int | float)
            or isinstance(value, bool)
            or not math.isfinite(value)
        ):
            raise InputError(f"{path}: intrinsics.{key} must be a finite number")
        centre.append(float(value))
    intrinsics = CameraIntrinsics(*size, *focal, *centre)
    transform = document.get("T_robot_camera")
    if transform is not None:
        transform = rigid_transform(transform, "T_robot_camera", path)
        check_distance(transform[:3, 3], f"{path}: T_robot_camera's translation", UNITS_IN_METRES)
    height = document.get("table_height_m")
    if height is not None and (
        not isinstance(height, int | float) or isinstance(height, bool) or not math.isfinite(height)
    ):
        raise InputError(f"{path}: table_height_m must be a number or null")
    return CameraFile(intrinsics, transform, None if height is None else float(height))
