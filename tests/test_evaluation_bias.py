"""The estimated bias scored against the true motion of the camera's cloud: hand-computed
errors and NEES, a zero error when the bias reproduces the motion on points, and the trial
that recovers the camera's calibration error as Stage 0's error."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from pipeline.config import load_config
from pipeline.experiments.paper_report import BIAS_NEES_BOUND, chi_square_4_quantile
from pipeline.metrics.evaluation import bias_errors
from pipeline.run.trial import run_trial
from pipeline.testing import AnalyticWorld, registry_with
from pipeline.types import Bias, SymmetryPlane

PIVOT = np.array([0.5, -0.1, 0.12])


def _motion(yaw_rad: float, about_m, translation_m) -> np.ndarray:
    """A turn by ``yaw_rad`` about the vertical through ``about_m``, then a translation."""
    motion = np.eye(4)
    motion[:3, :3] = Rotation.from_euler("z", yaw_rad).as_matrix()
    motion[:3, 3] = np.asarray(about_m) - motion[:3, :3] @ about_m + translation_m
    return motion


def test_a_translation_error_is_split_across_and_along_the_plane_by_hand():
    motion = _motion(0.0, PIVOT, [0.010, 0.0, 0.0])
    bias = Bias(yaw_rad=0.01, translation_m=[0.012, 0.001, 0.0], pivot_m=PIVOT)
    stds = np.array([0.02, 0.004, 0.002, 0.001])
    covariance = np.diag(np.concatenate([stds, [0.03, 0.4]]) ** 2)
    plane = SymmetryPlane(theta_rad=0.0, offset_m=0.5)  # normal along x
    scores = bias_errors(bias, covariance, plane, motion)
    assert scores["bias_yaw_error_deg"] == pytest.approx(np.degrees(0.01))
    assert scores["bias_across_error_mm"] == pytest.approx(2.0)
    assert scores["bias_along_error_mm"] == pytest.approx(1.0)
    assert scores["bias_yaw_std_deg"] == pytest.approx(np.degrees(0.02))
    assert scores["bias_across_std_mm"] == pytest.approx(4.0)
    assert scores["bias_along_std_mm"] == pytest.approx(2.0)
    expected = (0.01 / 0.02) ** 2 + (0.002 / 0.004) ** 2 + (0.001 / 0.002) ** 2
    assert scores["bias_nees"] == pytest.approx(expected)


def test_a_bias_that_moves_points_as_the_motion_does_has_no_error():
    motion = _motion(np.radians(-7.5), [0.48, -0.09, 0.0], [-0.004, 0.003, 0.0])
    points = PIVOT + np.random.default_rng(0).normal(scale=0.05, size=(50, 3))
    moved = points @ motion[:3, :3].T + motion[:3, 3]
    # The bias about PIVOT that moves PIVOT where the motion does: found by fitting points.
    shift = moved.mean(axis=0) - points.mean(axis=0)
    rough = Bias(yaw_rad=np.radians(-7.5), translation_m=shift, pivot_m=PIVOT)
    exact = Bias(
        yaw_rad=np.radians(-7.5),
        translation_m=rough.translation_m + (moved - rough.apply(points)).mean(axis=0),
        pivot_m=PIVOT,
    )
    np.testing.assert_allclose(exact.apply(points), moved, atol=1e-12)
    plane = SymmetryPlane(theta_rad=0.3, offset_m=0.4)
    scores = bias_errors(exact, np.eye(6) * 1e-6, plane, motion)
    for name in ("yaw_error_deg", "across_error_mm", "along_error_mm", "nees"):
        assert scores[f"bias_{name}"] == pytest.approx(0.0, abs=1e-9)


def test_the_nees_of_errors_drawn_from_the_covariance_is_chi_square_with_four_dof():
    rng = np.random.default_rng(1)
    root = rng.normal(size=(6, 6)) * 1e-3
    covariance = root @ root.T + np.eye(6) * 1e-8
    plane = SymmetryPlane(theta_rad=1.0, offset_m=0.2)
    motion = _motion(0.05, PIVOT, [0.01, 0.02, 0.0])
    true_yaw = 0.05
    true_shift = motion[:3, :3] @ PIVOT + motion[:3, 3] - PIVOT
    samples = rng.multivariate_normal(np.zeros(4), covariance[:4, :4], size=4000)
    nees = [
        bias_errors(
            Bias(yaw_rad=true_yaw + e[0], translation_m=true_shift + e[1:], pivot_m=PIVOT),
            covariance,
            plane,
            motion,
        )["bias_nees"]
        for e in samples
    ]
    assert np.mean(nees) == pytest.approx(4.0, rel=0.05)
    assert np.mean(np.array(nees) > BIAS_NEES_BOUND) == pytest.approx(0.01, abs=0.006)
    assert chi2.ppf(0.99, 4) == pytest.approx(BIAS_NEES_BOUND)


@pytest.mark.parametrize("probability", [1e-6, 0.01, 0.5, 0.9, 0.99, 0.999, 1.0 - 1e-12])
def test_the_closed_form_chi_square_quantile_is_scipys(probability):
    assert chi_square_4_quantile(probability) == pytest.approx(chi2.ppf(probability, 4), rel=1e-12)


def test_a_covariance_that_claims_a_wrong_component_exactly_known_scores_inf():
    covariance = np.diag([1e-4, 0.0, 1e-6, 1e-6, 1e-3, 0.1])
    bias = Bias(translation_m=[0.001, 0.0, 0.0], pivot_m=PIVOT)
    scores = bias_errors(bias, covariance, SymmetryPlane(0.0, 0.5), np.eye(4))
    assert scores["bias_nees"] == np.inf


def test_a_trial_scores_stage_0_by_the_cameras_calibration_error(tmp_path):
    """Nothing moves in the analytic world, so the true bias undoes the camera's calibration
    error; VC starts with no bias yaw, so Stage 0's yaw error is that error's yaw."""
    registry = registry_with(AnalyticWorld)
    overrides = [
        "world.use=analytic",
        "trial.gripper=parallel",
        "trial.pictures=false",
        "sensor.pybullet-kinect.calibration_yaw_deg=2.0",
    ]
    run_trial(load_config(registry, overrides=overrides), registry, tmp_path / "trial")
    stages = json.loads((tmp_path / "trial" / "result.json").read_text())["stages"]
    assert stages[0]["bias"]["yaw"] == 0.0
    assert stages[0]["metrics"]["bias_yaw_error_deg"] == pytest.approx(2.0, abs=1e-6)
    assert all(np.isfinite(stage["metrics"]["bias_nees"]) for stage in stages)
