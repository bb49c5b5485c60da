"""Shared machinery of the synthetic cylinder studies (paper Figs. 8, 9, 10; docs/method.md §7).

One trial: generate a noisy single-view cloud of a 40 mm radius cylinder and the contacts of
one top grasp (:func:`pipeline.synthetic.make_case`), run the estimator, and score every stage
by the error of the cylinder diameter fitted to its completed cloud (Taubin circle fit).

Task parameters are JSON with explicit units in their names, degrees and millimetres (this is
the file boundary; everything is converted to SI before it reaches the generator):

    gripper            "parallel" | "three_finger"
    tactile_angle_deg  grasp angle relative to the view
    theta_deg, r_mm    initial symmetry-plane error
    bias_mm            horizontal bias magnitude
    bias_direction_deg its direction about +z
    seed               the trial's random seed (cloud noise)
    estimator          estimator name; estimator_params: its parameter overrides

Result rows add ``bias_to_pads_deg`` (the bias direction relative to the nearest pad,
:attr:`~pipeline.synthetic.cases.SyntheticCase.bias_to_pads_rad`),
``stage{k}_diameter_error_mm`` (None when the completed cloud admits no circle
fit), ``stage{k}_status``, ``stage{k}_iterations``, ``stage{k}_seconds``,
``stage{k}_hypothesis`` (empty unless an alternative hypothesis replaced the fused model,
docs/method.md §9) for k = 0, 1, 2 (as far as the estimator returns stages), and the cloud
and contact sizes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.experiments import ExperimentOptions, SweepTask
from pipeline.experiments.common import plugin_registry, task_seed
from pipeline.io.formats import (
    consistency_fields,
    consistency_to_json,
    hypothesis_field,
    hypothesis_to_json,
)
from pipeline.metrics import diameter_error
from pipeline.run.runner import run_estimator
from pipeline.stages import Estimator
from pipeline.synthetic import make_case

#: The config sections a synthetic trial reads: no scene, sensor or hand is simulated.
CONFIG_SECTIONS = ("estimator",)


#: Full grids of the initial plane error (paper Fig. 8/9 axes: theta 0..90 deg).
THETA_DEG_FULL = tuple(float(v) for v in np.arange(0.0, 90.01, 11.25))


R_MM_FULL = tuple(float(v) for v in np.arange(-50.0, 50.01, 10.0))


def make_estimator(name: str, params: Mapping[str, Any]) -> Estimator:
    """The estimator ``name`` from the plugin registry, with validated parameter overrides."""
    return plugin_registry().create("estimator", name, dict(params))


def trial_params(
    options: ExperimentOptions,
    key: str,
    *,
    gripper: str,
    tactile_angle_deg: float,
    theta_deg: float,
    r_mm: float,
    bias_mm: float = 0.0,
    bias_direction_deg: float = 0.0,
    default_estimator_params: Mapping[str, Any] | None = None,
) -> SweepTask:
    # Nine parameters: one grid cell's coordinates, keyword-only, as the study's loops name them.
    """A :class:`SweepTask` for one trial; user overrides win over the experiment's defaults."""
    estimator_params = dict(default_estimator_params or {}) if options.estimator == "iekf" else {}
    estimator_params.update(options.estimator_params)
    return SweepTask(
        key=key,
        params={
            "gripper": gripper,
            "tactile_angle_deg": float(tactile_angle_deg),
            "theta_deg": float(theta_deg),
            "r_mm": float(r_mm),
            "bias_mm": float(bias_mm),
            "bias_direction_deg": float(bias_direction_deg),
            "seed": task_seed(options.seed, key),
            "estimator": options.estimator,
            "estimator_params": estimator_params,
        },
    )


def grid_tasks(
    options: ExperimentOptions,
    *,
    gripper: str,
    tactile_angles_deg: Sequence[float],
    thetas_deg: Sequence[float],
    rs_mm: Sequence[float],
    default_estimator_params: Mapping[str, Any] | None = None,
) -> list[SweepTask]:
    """Every (tactile angle, theta, r) combination, ``options.repeats`` times (default 1)."""
    repeats = options.repeats or 1
    tasks = []
    for phi in tactile_angles_deg:
        for theta in thetas_deg:
            for r in rs_mm:
                for repeat in range(repeats):
                    key = f"{gripper}/phi{phi:+g}/theta{theta:g}/r{r:+g}"
                    if repeats > 1:
                        key += f"/rep{repeat}"
                    tasks.append(
                        trial_params(
                            options,
                            key,
                            gripper=gripper,
                            tactile_angle_deg=phi,
                            theta_deg=theta,
                            r_mm=r,
                            default_estimator_params=default_estimator_params,
                        )
                    )
    return tasks


@dataclass(frozen=True)
class Draws:
    """The ranges a randomised study draws each trial's case from, uniformly.

    Attributes:
        tactile_deg: the grasp's angle relative to the view (deg).
        theta_deg, r_mm: the initial plane error (deg, mm).
    """

    tactile_deg: tuple[float, float]
    theta_deg: tuple[float, float]
    r_mm: tuple[float, float]


def random_tasks(
    options: ExperimentOptions,
    *,
    gripper: str,
    count: int,
    draws: Draws,
    bias_mm: float = 0.0,
    default_estimator_params: Mapping[str, Any] | None = None,
) -> list[SweepTask]:
    """``count`` trials whose tactile angle, plane error and bias direction are drawn
    uniformly (the direction over the full turn), each from a generator seeded by its key,
    so a trial's case does not depend on which others the sweep holds."""
    tasks = []
    for k in range(count):
        key = f"{gripper}/bias{bias_mm:g}/trial{k}"
        rng = np.random.default_rng(task_seed(options.seed, key + "/draw"))
        tasks.append(
            trial_params(
                options,
                key,
                gripper=gripper,
                tactile_angle_deg=float(rng.uniform(*draws.tactile_deg)),
                theta_deg=float(rng.uniform(*draws.theta_deg)),
                r_mm=float(rng.uniform(*draws.r_mm)),
                bias_mm=bias_mm,
                bias_direction_deg=float(rng.uniform(0.0, 360.0)),
                default_estimator_params=default_estimator_params,
            )
        )
    return tasks


def _diameter_error_mm(points: np.ndarray, true_diameter_m: float) -> float | None:
    if not np.all(np.isfinite(points)):
        return None
    try:
        return 1e3 * diameter_error(points, true_diameter_m)
    except ValueError:
        return None


def run_trial(params: Mapping[str, Any]) -> dict[str, Any]:
    """Run one synthetic trial from its JSON parameters; return the result fields."""
    rng = np.random.default_rng(int(params["seed"]))
    case = make_case(
        rng,
        gripper=params["gripper"],
        tactile_angle_rad=math.radians(params["tactile_angle_deg"]),
        theta_error_rad=math.radians(params["theta_deg"]),
        r_error_m=1e-3 * params["r_mm"],
        bias_magnitude_m=1e-3 * params["bias_mm"],
        bias_direction_rad=math.radians(params["bias_direction_deg"]),
    )
    estimator = make_estimator(params["estimator"], params["estimator_params"])
    result = run_estimator(estimator, case.problem)
    row: dict[str, Any] = {
        "points": len(case.cloud),
        "contacts": len(case.contacts),
        "selected_stage": result.selected.stage,
        "bias_to_pads_deg": math.degrees(case.bias_to_pads_rad),
    }
    for stage in result.stages:
        prefix = f"stage{stage.stage}"
        row[f"{prefix}_diameter_error_mm"] = _diameter_error_mm(
            stage.completed, case.cylinder.diameter_m
        )
        row[f"{prefix}_status"] = stage.status
        row[f"{prefix}_iterations"] = int(stage.iterations)
        row[f"{prefix}_seconds"] = float(stage.seconds)
        row.update(consistency_fields(prefix, consistency_to_json(stage.consistency)))
        row.update(hypothesis_field(prefix, hypothesis_to_json(stage.hypothesis)))
    return row
