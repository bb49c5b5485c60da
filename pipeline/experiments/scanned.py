"""Trials on scanned meshes (e.g. YCB): which hand, initialiser and yaw suit the object."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..perception.grasp_geometry import narrowest_width
from . import ExperimentOptions
from .common import plugin_registry
from .paper_tasks import camera_azimuth_deg


def scan_trial_params(
    mesh_path: Path,
    *,
    seed: int = 0,
    estimator: str = "iekf",
    estimator_params: Mapping[str, Any] | None = None,
    trial_dir: Path | None = None,
) -> dict[str, Any]:
    """Task params of one trial on a scanned mesh file (e.g. a YCB ``textured.obj``).

    The PG-70 is used when the object's narrowest horizontal width plus the default
    planner's jaw clearance (its ``jaw_clearance_m``) fits the PG-70 aperture (as the
    default world describes the hand) (PS
    initialisation, the narrow direction turned toward the default sensor's camera so the
    jaws close along it); otherwise the SDH-2 (VC initialisation, three-finger top grasp,
    object yaw 0).

    Raises:
        ConfigError: the default planner has no ``jaw_clearance_m``, or the default sensor
            no ``azimuth_deg``.
    """
    from ..catalogue import load_object
    from ..config import load_config

    registry = plugin_registry()
    defaults = load_config(registry)
    clearance_m = getattr(defaults.stage_params("planner"), "jaw_clearance_m", None)
    if clearance_m is None:
        raise ConfigError(
            f"planner '{defaults.choices['planner']}' has no jaw_clearance_m parameter: "
            "scanned-mesh trials fit the object between parallel jaws"
        )
    mesh = load_object(mesh_path).mesh
    width_m, direction_rad = narrowest_width(np.asarray(mesh.vertices)[:, :2])
    pg70 = defaults.create(registry, "world").gripper_spec("pg70")
    if width_m + clearance_m <= pg70.max_aperture_m:
        gripper, init, overrides = "pg70", "ps", []
        azimuth_deg = camera_azimuth_deg(ExperimentOptions())
        yaw_deg = math.degrees(math.radians(azimuth_deg) - direction_rad)
    else:
        gripper, init, overrides = "sdh", "vc", ["planner.use=top-three-finger"]
        yaw_deg = 0.0
    return {
        "object": str(mesh_path),
        "init": init,
        "gripper": gripper,
        "view_offset_deg": 0.0,
        "yaw_deg": (yaw_deg + 180.0) % 360.0 - 180.0,
        "narrowest_width_mm": 1e3 * width_m,
        "seed": int(seed),
        "overrides": overrides,
        "estimator": estimator,
        "estimator_params": dict(estimator_params or {}),
        "trial_dir": None if trial_dir is None else str(trial_dir),
    }
