"""The initialiser-accuracy experiment: its grid and its success criterion."""

from __future__ import annotations

import pytest

from pipeline.experiments import EXPERIMENTS, ExperimentOptions
from pipeline.experiments import init as experiment


def test_grid_is_objects_by_yaws_by_initialisers_with_shared_yaws():
    tasks = experiment.tasks(ExperimentOptions(seed=3))
    assert EXPERIMENTS["init"].module is experiment
    assert len(tasks) == len(experiment.OBJECTS) * experiment.YAWS * len(experiment.INITS)
    assert len({t.key for t in tasks}) == len(tasks)
    by_yaw = {}
    for task in tasks:
        object_yaw = (task.params["object"], task.key.rsplit("/", 1)[1])
        by_yaw.setdefault(object_yaw, set()).add((task.params["yaw_deg"], task.params["seed"]))
    # every initialiser sees the same scene (yaw and seed) for a given object and yaw index
    assert all(len(scenes) == 1 for scenes in by_yaw.values())
    assert {t.params["estimator"] for t in tasks} == {"mirror-only"}
    yaws = [t.params["yaw_deg"] for t in tasks]
    assert min(yaws) >= -180.0 and max(yaws) <= 180.0


@pytest.mark.parametrize(
    ("row", "hit"),
    [
        ({"stage0_plane_offset_error_mm": 3.0, "stage0_plane_angle_error_deg": 9.0}, True),
        ({"stage0_plane_offset_error_mm": 11.0, "stage0_plane_angle_error_deg": 1.0}, False),
        ({"stage0_plane_offset_error_mm": 1.0, "stage0_plane_angle_error_deg": 12.0}, False),
        ({"stage0_plane_offset_error_mm": 1.0}, True),  # rotational: offset only
        ({"failed": "grasp planner refused", "status": "failed"}, False),
        ({"error": "ValueError: boom"}, False),
    ],
)
def test_success_needs_both_tolerances_and_a_finished_trial(row, hit):
    assert experiment.succeeded(row) is hit
