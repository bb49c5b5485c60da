"""The three estimator plugins through the stage contract."""

from __future__ import annotations

import numpy as np
import pytest
from estimation_scenes import cylinder_scene

from pipeline.errors import ConfigError, StageFailure
from pipeline.types import (
    Bias,
    Contacts,
    EstimationProblem,
    PointCloud,
    SymmetryInit,
    SymmetryPlane,
)
from plugins.estimators.icp import IcpEstimator
from plugins.estimators.iekf import IekfEstimator
from plugins.estimators.mirror_only import MirrorOnlyEstimator


@pytest.fixture(scope="module")
def scene():
    # 1000 points (3.5 mm apart): in a sparser cloud most taxel windows (1.7 mm std) hold
    # one point or none, and eq. 9's weighted means jump from point to point.
    return cylinder_scene(1000, seed=11)


def _problem(scene, points=None):
    contacts = Contacts(
        positions=scene.taxels_m,
        normals=scene.normals,
        pads=scene.pads,
        taxel_indices=np.arange(len(scene.taxels_m)),
    )
    # Initial bias about the robot origin: the plugin must re-express it about its pivot.
    init = SymmetryInit(
        plane=SymmetryPlane(theta_rad=0.08, offset_m=0.008),
        bias=Bias(yaw_rad=0.0, translation_m=np.zeros(3), pivot_m=np.zeros(3)),
    )
    cloud = PointCloud(scene.points_m if points is None else points)
    return EstimationProblem(cloud=cloud, init=init, grasps=(contacts,))


def _error(scene, stage):
    return scene.surface_distance(stage.completed).mean()


@pytest.mark.parametrize("estimator", [IekfEstimator(), IcpEstimator()])
@pytest.mark.slow
def test_fusing_estimators_improve_on_the_initial_model(scene, estimator):
    result = estimator.estimate(_problem(scene))
    assert [s.stage for s in result.stages] == [0, 1, 2]
    assert result.stage(0).status == "initial"
    np.testing.assert_allclose(result.stage(0).bias.pivot_m, scene.points_m.mean(axis=0))
    for stage in result.stages:
        assert stage.completed.shape == (2 * len(scene.points_m), 3)
        assert stage.covariance.shape == (6, 6)
    assert result.final.status in ("converged", "max_iterations")
    assert result.final.iterations > 0
    assert _error(scene, result.final) < 0.5 * _error(scene, result.stage(0))


def test_iekf_can_stop_after_stage_one(scene):
    params = IekfEstimator.Params(last_stage=1)
    result = IekfEstimator(params).estimate(_problem(scene))
    assert [s.stage for s in result.stages] == [0, 1]
    np.testing.assert_array_equal(result.final.points, scene.points_m)


def test_mirror_only_repeats_the_initial_completion(scene):
    result = MirrorOnlyEstimator().estimate(_problem(scene))
    expected = np.vstack([scene.points_m, SymmetryPlane(0.08, 0.008).mirror(scene.points_m)])
    for stage in result.stages:
        np.testing.assert_allclose(stage.completed, expected, atol=1e-15)
        assert stage.iterations == 0
    assert [s.status for s in result.stages] == ["initial", "converged", "converged"]


def test_bad_parameters_and_inputs_are_reported(scene):
    with pytest.raises(ConfigError, match="point_std_m"):
        IekfEstimator(IekfEstimator.Params(point_std_m=0.0))
    with pytest.raises(ConfigError, match="max_iterations"):
        IekfEstimator(IekfEstimator.Params(max_iterations=0))
    with pytest.raises(StageFailure, match="empty"):
        IekfEstimator().estimate(_problem(scene, points=np.zeros((0, 3))))


def test_iekf_traces_every_iteration_and_ends_at_the_stage_estimate(scene):
    """One trace entry per iteration; each stage's last entry is that stage's state; the
    taxel counts are bounded by the grasp's taxels; the trace reaches result.json."""
    from pipeline.io.formats import estimate_to_json

    result = IekfEstimator().estimate(_problem(scene))
    assert result.stage(0).trace == ()
    for stage in result.stages[1:]:
        assert len(stage.trace) == stage.iterations
        last = stage.trace[-1]
        assert last.plane == stage.plane
        assert last.bias.yaw_rad == stage.bias.yaw_rad
        np.testing.assert_array_equal(last.bias.translation_m, stage.bias.translation_m)
        assert all(0 < s.active_taxels <= len(scene.taxels_m) for s in stage.trace)
        assert all(s.active_points > 0 and s.grasp == 0 for s in stage.trace)
    stage_one = estimate_to_json(result)[1]
    assert len(stage_one["trace"]) == result.stage(1).iterations
    assert stage_one["trace"][-1]["plane"] == stage_one["plane"]


def test_icp_declares_only_the_parameters_it_uses(run):
    icp = set(IcpEstimator.Params.__dataclass_fields__)
    iekf = set(IekfEstimator.Params.__dataclass_fields__)
    # The IEKF's correspondence window, weights and iteration control mean nothing to ICP.
    for name in ("window_along_normal_m", "schedule", "exclusive_sides", "facing_filter"):
        assert name in iekf and name not in icp
    for name in ("refine_gates", "gate_tolerance_m", "tolerance_m", "max_step_m"):
        assert name in iekf and name not in icp
    assert {"max_match_distance_m", "max_iterations", "prior_m_theta_rad"} <= icp
    code, out, _ = run("plugins", "--params")
    assert code == 0
    section = out.split("[estimator.icp]")[1].split("\n[")[0]
    shown = {line.split("=")[0].strip() for line in section.splitlines() if "=" in line}
    assert shown == icp


def test_an_iekf_parameter_given_to_icp_is_an_unknown_key(run, tmp_path):
    code, _, err = run(
        "trial",
        "--set",
        "estimator.use=icp",
        "--set",
        "estimator.icp.schedule=standard",
        "--out",
        tmp_path / "trial",
    )
    assert code == ConfigError.exit_code
    assert "unknown config key 'estimator.icp.schedule'" in err
    assert not (tmp_path / "trial").exists()
