"""The real-object experiments' task grids, config overrides and pure helpers
(pipeline/experiments/paper_tasks.py, paper_trial.py, the table1-3 rows, spray, kth)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pipeline.catalogue.objects import list_objects
from pipeline.config import load_config
from pipeline.experiments import EXPERIMENTS, ExperimentOptions, kth
from pipeline.experiments.measure_report import measure_statistics
from pipeline.experiments.paper_tasks import (
    camera_azimuth_deg,
    reference_yaw_deg,
    trial_overrides,
)
from pipeline.experiments.paper_trial import DIVERGED_GROWTH_MM, is_diverged
from pipeline.experiments.rows import mean_five_numbers
from pipeline.planning.grasp_geometry import narrowest_width
from pipeline.registry import load_registry

PAPER_EXPERIMENTS = ("table1", "table2", "table3", "spray", "kth")


@pytest.fixture(scope="module")
def registry():
    return load_registry()


def _module(name):
    return EXPERIMENTS[name]


def test_experiments_are_registered_with_the_protocol():
    for name in PAPER_EXPERIMENTS:
        experiment = _module(name)
        assert name == experiment.name
        assert experiment.description
        for function in ("tasks", "run_one", "report"):
            assert callable(getattr(experiment, function))


@pytest.mark.parametrize(
    ("name", "full", "objects"),
    [
        ("table1", 10, {"cd_drive"}),
        ("table2", 10, {"plastic_case"}),
        ("table3", 10, {"salt_cylinder"}),
        ("spray", 10, {"spray_bottle"}),
        ("kth", 29, set(kth.POSES)),
    ],
)
def test_grids_have_the_papers_sizes_and_unique_json_tasks(name, full, objects):
    module = _module(name)
    tasks = module.tasks(ExperimentOptions())
    assert len(tasks) == full
    assert len({task.key for task in tasks}) == full
    assert {task.params["object"] for task in tasks} == objects
    for task in tasks:
        assert json.loads(json.dumps(dict(task.params))) == dict(task.params)
    quick = module.tasks(ExperimentOptions(quick=True))
    assert 2 <= len(quick) <= 3
    doubled = module.tasks(ExperimentOptions(repeats=2))
    # kth's repeats is the number of poses per object; the others repeat every pose
    assert len(doubled) == (2 * len(kth.POSES) if name == "kth" else 2 * full)


def test_seeds_are_stable_and_differ_between_tasks():
    first = _module("table1").tasks(ExperimentOptions(seed=3))
    again = _module("table1").tasks(ExperimentOptions(seed=3))
    other = _module("table1").tasks(ExperimentOptions(seed=4))
    assert [t.params["seed"] for t in first] == [t.params["seed"] for t in again]
    assert len({t.params["seed"] for t in first}) == len(first)
    assert [t.params["seed"] for t in first] != [t.params["seed"] for t in other]


def test_kth_poses_follow_table4_and_spread_over_the_yaw_range():
    tasks = _module("kth").tasks(ExperimentOptions())
    counts = {}
    for task in tasks:
        counts[task.params["object"]] = counts.get(task.params["object"], 0) + 1
        assert task.params["gripper"] == "sdh"
        assert task.params["init"] == "vc"
    assert counts == {"box": 4, "bread": 1, "coffee": 5, "cup": 8, "jam": 3,
                      "salt_cylinder_kth": 2, "saltbox": 5, "sedan": 1}  # fmt: skip
    cup = sorted(t.params["view_offset_deg"] for t in tasks if t.params["object"] == "cup")
    assert cup[0] == pytest.approx(-kth.YAW_SPREAD_DEG)
    assert cup[-1] == pytest.approx(kth.YAW_SPREAD_DEG)
    assert np.allclose(np.diff(cup), 2 * kth.YAW_SPREAD_DEG / 7)


@pytest.mark.parametrize("azimuth_deg", [180.0, 135.0, -60.0])
def test_reference_yaw_points_the_mirror_normal_along_the_view(azimuth_deg):
    view = -np.array([math.cos(math.radians(azimuth_deg)), math.sin(math.radians(azimuth_deg))])
    for info in list_objects():
        yaw = math.radians(reference_yaw_deg(info.name, azimuth_deg))
        if info.symmetry_plane is None:
            assert yaw == 0.0
            continue
        theta = info.symmetry_plane.theta_rad + yaw
        normal = np.array([math.cos(theta), math.sin(theta)])
        assert abs(normal @ view) == pytest.approx(1.0, abs=1e-12), info.name


def test_the_camera_azimuth_is_the_configured_sensors():
    assert camera_azimuth_deg(ExperimentOptions()) == 180.0
    moved = ExperimentOptions(
        quick=True, config={"sensor": {"pybullet-kinect": {"azimuth_deg": 150.0}}}
    )
    assert camera_azimuth_deg(moved) == 150.0
    stereo = ("sensor.use=pybullet-stereo", "sensor.pybullet-stereo.azimuth_deg=120")
    assert camera_azimuth_deg(ExperimentOptions(), stereo) == 120.0
    # a user who turns the camera turns every object's reference pose with it
    table1 = EXPERIMENTS["table1"]
    default = table1.tasks(ExperimentOptions(quick=True))[0].params["yaw_deg"]
    turned = table1.tasks(moved)[0].params["yaw_deg"]
    assert (turned - default) % 180.0 == pytest.approx((150.0 - 180.0) % 180.0)


def test_overrides_build_the_trial_config(registry):
    options = ExperimentOptions(estimator="iekf", estimator_params={"max_iterations": 7})
    task = _module("kth").tasks(options)[0]
    config = load_config(registry, overrides=trial_overrides(task.params))
    assert config.trial.object == task.params["object"]
    assert config.trial.gripper == "sdh"
    assert config.trial.seed == task.params["seed"]
    assert config.trial.yaw_deg == pytest.approx(task.params["yaw_deg"])
    assert config.choices["initialiser"] == "vc"
    assert config.choices["planner"] == "top-three-finger"
    assert config.stage_params("planner").strategy == "paper"
    assert config.choices["sensor"] == "pybullet-stereo"
    assert config.stage_params("estimator").max_iterations == 7


def test_overrides_select_another_estimator(registry):
    options = ExperimentOptions(estimator="mirror-only", estimator_params={})
    task = _module("table3").tasks(options)[0]
    config = load_config(registry, overrides=trial_overrides(task.params))
    assert config.choices["estimator"] == "mirror-only"
    assert config.choices["planner"] == "top-parallel"
    assert config.trial.gripper == "pg70"
    assert config.stage_params("planner").strategy == "paper"


def test_a_sweeps_trials_draw_pictures_only_when_the_user_names_them(registry):
    """The trials leave pictures out (the report draws its own) unless the user's config
    names ``trial.pictures``; ``--set trial.pictures=true`` names it at the default's value."""
    from pipeline.cli.sweep import user_settings

    for named, pictures in (([], False), (["trial.pictures=true"], True)):
        user = user_settings(load_config(registry, overrides=named))
        task = _module("table3").tasks(ExperimentOptions(config=user, quick=True))[0]
        config = load_config(registry, overrides=trial_overrides(task.params))
        assert config.trial.pictures is pictures


def test_narrowest_width_of_a_rotated_rectangle():
    angle = math.radians(30.0)
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    corners = np.array([[-0.05, -0.02], [0.05, -0.02], [0.05, 0.02], [-0.05, 0.02]])
    rng = np.random.default_rng(1)
    inside = rng.uniform([-0.05, -0.02], [0.05, 0.02], size=(200, 2))
    width, direction = narrowest_width(np.vstack([corners, inside]) @ rotation.T)
    assert width == pytest.approx(0.04, abs=1e-12)
    # the short side is along the rectangle's y axis, rotated by 30 deg: 120 deg
    assert direction == pytest.approx(math.radians(120.0), abs=1e-9)


def test_narrowest_width_matches_a_dense_angle_search():
    rng = np.random.default_rng(7)
    points = rng.normal(size=(100, 2)) * [0.03, 0.01]
    width, direction = narrowest_width(points)
    angles = np.linspace(0.0, math.pi, 200_001)
    projections = points @ np.vstack([np.cos(angles), np.sin(angles)])
    widths = projections.max(axis=0) - projections.min(axis=0)
    assert width == pytest.approx(widths.min(), rel=1e-4)
    assert width <= widths.min() + 1e-12
    along = points @ [math.cos(direction), math.sin(direction)]
    assert along.max() - along.min() == pytest.approx(width, rel=1e-12)


def test_measure_statistics_are_the_papers_error_of_the_mean():
    rows = [
        {"stage2_thickness_mm": 41.0},
        {"stage2_thickness_mm": 45.0},
        {"stage2_thickness_mm": None},
    ]
    stats = measure_statistics(rows, "thickness", 42.0, 2)
    assert stats["mean"] == pytest.approx(43.0)
    assert stats["std"] == pytest.approx(math.sqrt(8.0))
    assert stats["error_pct"] == pytest.approx(100.0 / 42.0)
    assert stats["abs_error_pct"] == pytest.approx(2.0 / 42.0 * 100.0)
    assert math.isnan(measure_statistics(rows[2:], "thickness", 42.0, 2)["mean"])


def test_mean_five_numbers_averages_each_quantile():
    def row(offset):
        return {
            f"stage1_deviation_{name}_mm": offset + k
            for k, name in enumerate(("min", "q1", "median", "q3", "max"))
        }

    box = mean_five_numbers([row(0.0), row(2.0)], 1)
    assert np.allclose(box, [1.0, 2.0, 3.0, 4.0, 5.0])
    # drawn as a sample, its percentiles are the box itself
    assert np.allclose(np.percentile(box, [0, 25, 50, 75, 100]), box)


def test_diverged_by_status_or_by_deviation_growth():
    base = {"stage0_status": "initial", "stage0_deviation_median_mm": 4.0}
    assert is_diverged({**base, "stage2_status": "diverged", "stage2_deviation_median_mm": 1.0})
    grown = {**base, "stage2_status": "converged"}
    assert is_diverged({**grown, "stage2_deviation_median_mm": 4.0 + DIVERGED_GROWTH_MM + 0.1})
    assert not is_diverged({**grown, "stage2_deviation_median_mm": 4.0 + DIVERGED_GROWTH_MM})
    assert not is_diverged({**grown, "stage2_deviation_median_mm": 1.0})
