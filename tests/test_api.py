"""pipeline.api: the public names exist, import nothing heavy, and the estimate builder
completes the model as the types' own mirror and bias say."""

from __future__ import annotations

import numpy as np
import pytest
from test_import_cost import HEAVY, loaded_after

import pipeline.api as api


def test_every_public_name_exists():
    missing = [name for name in api.__all__ if not hasattr(api, name)]
    assert missing == []
    assert len(api.STAGES) == 7 and api.World in api.StageImplementation.__subclasses__()


def test_importing_the_api_loads_no_heavy_library():
    assert loaded_after("import pipeline.api", (*HEAVY, "scipy", "open3d")) == []


def test_the_simulated_worlds_and_built_in_planners_are_public_without_their_engines():
    code = (
        "from pipeline.api.sim import Pybullet, Mujoco; "
        "from pipeline.api.planning import TopParallel, TopThreeFinger; "
        "assert (Pybullet.name, Mujoco.name) == ('pybullet', 'mujoco'); "
        "assert (TopParallel.name, TopThreeFinger.name) == ('top-parallel', 'top-three-finger')"
    )
    assert loaded_after(code, ("pybullet", "mujoco")) == []


def test_stage_estimate_completes_the_model_with_the_mirror_and_the_bias():
    rng = np.random.default_rng(4)
    points = rng.uniform(-0.05, 0.05, (50, 3)) + np.array([0.5, 0.1, 0.05])
    plane = api.SymmetryPlane(theta_rad=0.3, offset_m=0.2)
    bias = api.Bias(yaw_rad=0.02, translation_m=[0.003, -0.001, 0.0], pivot_m=[0.5, 0.1, 0.05])
    covariance = np.diag([1e-4, 1e-6, 1e-6, 1e-6, 1e-6, 1e-4])
    stage = api.stage_estimate(1, plane, bias, points, covariance, "converged", iterations=4)
    assert stage.stage == 1 and stage.status == "converged" and stage.iterations == 4
    assert stage.plane == plane
    np.testing.assert_allclose(stage.bias.translation_m, bias.translation_m)
    np.testing.assert_allclose(stage.bias.pivot_m, bias.pivot_m)
    expected = np.vstack([bias.apply(points), bias.apply(plane.mirror(points))])
    np.testing.assert_allclose(stage.completed, expected, atol=1e-12)
    result = api.EstimateResult(stages=(stage,))
    assert result.final is stage and result.selected is stage


def test_cloud_points_refuses_an_empty_cloud():
    problem = api.EstimationProblem(
        cloud=api.PointCloud(np.zeros((0, 3))),
        init=api.SymmetryInit(api.SymmetryPlane(0.0, 0.0), api.Bias()),
        grasps=(),
    )
    with pytest.raises(api.StageFailure, match="estimator 'mine': the object cloud is empty"):
        api.cloud_points(problem, "mine")
