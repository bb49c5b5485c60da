"""Task grids and trial configs of the paper's real-object experiments, run in simulation.

One task is one full simulated trial (:func:`pipeline.run.trial.run_trial`): an object, an
initialiser (``ps`` or ``vc``), an object yaw and a seed.

Object yaw. The paper placed each object "in different pose compared to Kinect". Here a
trial's ``view_offset_deg`` is its yaw relative to the *reference view*, the yaw at which
the catalogue's symmetry-plane normal points along the camera's viewing direction (the
camera sees one half of the object squarely and mirroring completes the other; for
rotational objects the reference yaw is 0). The actual ``yaw_deg`` given to the trial is
stored in the params beside it. The camera is the configured sensor's viewpoint (its
``azimuth_deg`` about +z, looking at the object).

Task parameters (JSON; units in the names):

    object             catalogue name or mesh path
    init               initialiser name (``ps``, ``vc``)
    gripper            hand name (``trial.gripper``)
    view_offset_deg    yaw relative to the reference view; yaw_deg: the trial's object yaw
    seed               the trial's seed (scene, sensor and tactile noise)
    overrides          further ``--set`` strings of the experiment (planner, sensor)
    config             the user's config values other than the estimator's, where they
                       differ from the defaults; the trial's config starts from them
    estimator          estimator name; estimator_params: its parameters
    trial_dir          folder for the trial's files, or None (a temporary folder, deleted)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import tomli_w

from pipeline.catalogue.objects import list_objects
from pipeline.errors import ConfigError
from pipeline.experiments import ExperimentOptions, SweepTask
from pipeline.experiments.common import plugin_registry, task_seed

#: Object yaws relative to the reference view (deg): five poses, like the paper's five runs.
VIEW_OFFSETS_DEG = (-30.0, -15.0, 0.0, 15.0, 30.0)
#: The view offset of ``quick`` runs (deg).
QUICK_VIEW_OFFSET_DEG = 10.0


def camera_azimuth_deg(options: ExperimentOptions, overrides: Sequence[str] = ()) -> float:
    """Azimuth (deg about +z) from which the camera of the experiment's trials looks at the
    object: the ``azimuth_deg`` of the sensor the user's config and the experiment's
    ``overrides`` select.

    Raises:
        ConfigError: that sensor has no ``azimuth_deg`` (its viewpoint is not known before
            the trial runs, so no yaw can face the object toward it).
    """
    from pipeline.config import load_config

    config = load_config(
        plugin_registry(), settings=user_settings(options), overrides=list(overrides)
    )
    sensor = config.choices["sensor"]
    azimuth = getattr(config.stage_params("sensor"), "azimuth_deg", None)
    if azimuth is None:
        raise ConfigError(
            f"sensor '{sensor}' has no azimuth_deg parameter: the paper experiments turn each "
            "object relative to the camera's azimuth"
        )
    return float(azimuth)


def reference_yaw_deg(object_name: str, camera_azimuth_deg: float) -> float:
    """The yaw (deg, in (-90, 90]) at which the object's symmetry-plane normal lies along the
    viewing direction of a camera at ``camera_azimuth_deg`` about +z; 0 for objects without
    a single mirror plane."""
    infos = {info.name: info for info in list_objects()}
    if object_name not in infos:
        raise ConfigError(f"experiment object '{object_name}' is not in the catalogue")
    plane = infos[object_name].symmetry_plane
    if plane is None:
        return 0.0
    yaw = (camera_azimuth_deg - math.degrees(plane.theta_rad)) % 180.0
    return yaw - 180.0 if yaw > 90.0 else yaw


def trial_root(options: ExperimentOptions) -> Path | None:
    """Where per-trial folders go: ``<out_dir>/trials``, or None (trial files not kept)."""
    return None if options.out_dir is None else Path(options.out_dir) / "trials"


def user_settings(options: ExperimentOptions) -> dict[str, Any]:
    """The user's config changes a trial starts from (``config`` in the params); the
    estimator's travel as ``estimator`` and ``estimator_params``."""
    return {section: value for section, value in options.config.items() if section != "estimator"}


def sweep_params(options: ExperimentOptions, key: str) -> dict[str, Any]:
    """The task params every trial of a sweep shares: the user's config changes, the
    estimator with its parameters, and the trial's folder ``<out_dir>/trials/<key>`` (None
    when trials are not kept)."""
    root = trial_root(options)
    return {
        "config": user_settings(options),
        "estimator": options.estimator,
        "estimator_params": dict(options.estimator_params),
        "trial_dir": None if root is None else str(root / key),
    }


def paper_task(key: str, params: dict[str, Any]) -> SweepTask:
    """The task of ``params``, its :attr:`SweepTask.settings` from :func:`trial_overrides`."""
    return SweepTask(key=key, params=params, settings=tuple(trial_overrides(params)))


def object_tasks(
    options: ExperimentOptions,
    object_name: str,
    *,
    inits: Sequence[str],
    view_offsets_deg: Sequence[float],
    gripper: str = "pg70",
    overrides: Sequence[str] = (),
    repeats: int | None = None,
) -> list[SweepTask]:
    """One task per (init, view offset, repeat) for ``object_name``: ``repeats`` trials with
    different seeds per pose (default ``options.repeats``, else 1)."""
    root = trial_root(options)
    base_yaw = reference_yaw_deg(object_name, camera_azimuth_deg(options, overrides))
    repeats = repeats or options.repeats or 1
    tasks = []
    for init in inits:
        for offset in view_offsets_deg:
            for repeat in range(repeats):
                key = f"{object_name}/{init}/view{offset:+g}/rep{repeat}"
                tasks.append(
                    paper_task(
                        key,
                        {
                            "object": object_name,
                            "init": init,
                            "gripper": gripper,
                            "view_offset_deg": float(offset),
                            "yaw_deg": float(base_yaw + offset),
                            "seed": task_seed(options.seed, key),
                            "overrides": list(overrides),
                            "config": user_settings(options),
                            "estimator": options.estimator,
                            "estimator_params": dict(options.estimator_params),
                            "trial_dir": None if root is None else str(root / key),
                        },
                    )
                )
    return tasks


def toml_value(value: Any) -> str:
    """``value`` as a TOML literal, for the right-hand side of a ``--set`` override."""
    return tomli_w.dumps({"v": value}).partition("=")[2].strip()


#: The paper's grasps, whatever the planners' defaults: closing along the proposed plane's
#: normal at the object's top (``strategy = "paper"`` of both shipped planners).
PAPER_GRASP = ("planner.top-parallel.strategy=paper", "planner.top-three-finger.strategy=paper")
#: The paper's segmentation with it: everything less than 20 mm above the table cut, and
#: the planners told the table lies that far below the cloud. The cut that follows the
#: table's fit moved VC's Stage 0 (``table3`` 5.1 to 10.3 % diameter error; ``kth`` box
#: 2.5 to 3.5 mm) and the ``kth`` coffee's Stage 2 (0.7 to 1.0-1.2 mm): the reproductions
#: keep the paper's rule (docs/method.md §5).
PAPER_SEGMENTATION = (
    "segmenter.table-cluster.cut=fixed",
    "planner.top-parallel.cloud_base_above_table_m=0.02",
    "planner.top-three-finger.cloud_base_above_table_m=0.02",
)


def paper_view(params: Mapping[str, Any]) -> tuple[str, ...]:
    """The paper's single view (no after-view, docs/after-view.md) for a reproduction
    whose user config does not choose ``trial.after_view`` itself."""
    chosen = "after_view" in params.get("config", {}).get("trial", {})
    return () if chosen else ("trial.after_view=false",)


def sweep_pictures(params: Mapping[str, Any]) -> tuple[str, ...]:
    """No pictures in a sweep's trial (the sweep's report draws its own figures from the
    rows) unless the user's config chooses ``trial.pictures`` itself."""
    chosen = "pictures" in params.get("config", {}).get("trial", {})
    return () if chosen else ("trial.pictures=false",)


def trial_overrides(params: Mapping[str, Any]) -> list[str]:
    """The ``--set`` strings that turn the sweep's config into the trial of ``params``: its
    object, hand, seed, yaw and initialiser, its pictures (:func:`sweep_pictures`), the
    paper's grasp strategy, segmentation and single view (:data:`PAPER_GRASP`,
    :data:`PAPER_SEGMENTATION`, :func:`paper_view`, unless ``paper_grasp`` is false: the
    shipped defaults), the experiment's overrides and the estimator."""
    estimator = params["estimator"]
    paper = params.get("paper_grasp", True)
    overrides = [
        f"trial.object={toml_value(params['object'])}",
        f"trial.gripper={params['gripper']}",
        *sweep_pictures(params),
        *(PAPER_GRASP + PAPER_SEGMENTATION + paper_view(params) if paper else ()),
        f"trial.seed={int(params['seed'])}",
        f"trial.yaw_deg={toml_value(float(params['yaw_deg']))}",
        f"initialiser.use={params['init']}",
        *params["overrides"],
        f"estimator.use={estimator}",
    ]
    overrides += [
        f"estimator.{estimator}.{key}={toml_value(value)}"
        for key, value in params["estimator_params"].items()
    ]
    return overrides


def trial_config(params: Mapping[str, Any]):
    """The resolved config of the trial of ``params``: the defaults, then the user's
    changes (``config``), then the experiment's :func:`trial_overrides`."""
    from pipeline.config import load_config

    return load_config(
        plugin_registry(), settings=params.get("config", {}), overrides=trial_overrides(params)
    )
