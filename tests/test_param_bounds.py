"""Parameter bounds: a nonsense value is a config error naming its key, and every built-in
implementation's defaults satisfy its bounds."""

from __future__ import annotations

import pytest

from pipeline.config import load_config
from pipeline.errors import ConfigError
from pipeline.stages import STAGES
from pipeline.testing import AnalyticWorld, registry_with


@pytest.fixture(scope="module")
def registry():
    return registry_with(AnalyticWorld)


def build_stages(registry, overrides):
    config = load_config(registry, overrides=overrides)
    for stage in STAGES:
        config.create(registry, stage)


BAD_VALUES = [
    ("sensor.pybullet-kinect.width", "0"),
    ("sensor.pybullet-kinect.distance_m", "0"),
    ("sensor.pybullet-kinect.baseline_m", "0"),
    ("sensor.pybullet-kinect.disparity_step_px", "0"),
    ("sensor.pybullet-kinect.disparity_sigma_px", "-1"),
    ("sensor.pybullet-kinect.edge_margin_px", "-1"),
    ("sensor.pybullet-kinect.max_incidence_deg", "91"),
    ("sensor.pybullet-kinect.max_range_m", "-1"),
    ("sensor.pybullet-kinect.min_range_m", "5"),  # above max_range_m 4
    ("sensor.pybullet-kinect.near_m", "7"),  # beyond far_m 6
    ("sensor.pybullet-stereo.height", "0"),
    ("sensor.pybullet-stereo.baseline_m", "0"),
    ("sensor.pybullet-stereo.disparity_sigma_px", "-1"),
    ("sensor.pybullet-stereo.min_range_m", "3.5"),  # above max_range_m 3
    ("sensor.recorded.min_plane_fraction", "2"),
    ("segmenter.table-cluster.eps_m", "-0.01"),
    ("segmenter.table-cluster.eps_m", "0"),
    ("segmenter.table-cluster.min_points", "-1"),
    ("segmenter.table-cluster.voxel_m", "-1"),
    ("segmenter.table-cluster.ransac_iterations", "0"),
    ("segmenter.table-cluster.ransac_seed", "-1"),
    ("segmenter.table-cluster.min_object_points", "0"),
    ("segmenter.table-cluster.min_height_m", "2"),  # above max_height_m 1
    ("segmenter.table-cluster.min_height_m", "0.01"),  # read with cut = "fixed" only
    ("segmenter.table-cluster.cut_sigmas", "0"),
    ("segmenter.ground-truth-mask.ransac_inlier_m", "0"),
    ("initialiser.vc.orientations", "0"),
    ("initialiser.vc.offsets", "-1"),
    ("initialiser.vc.max_angle_deg", "-1"),
    ("initialiser.vc.max_angle_deg", "0"),  # with 19 orientations
    ("initialiser.vc.max_violation_fraction", "-1"),
    ("initialiser.vc.max_violation_fraction", "1.5"),
    ("planner.top-parallel.jaw_clearance_m", "-1"),
    ("planner.top-parallel.flat_radius_m", "0"),
    ("planner.top-parallel.back_margin_m", "-0.01"),
    ("planner.top-parallel.descent_clearance_m", "-0.01"),
    ("planner.top-three-finger.spread_deg", "91"),
    ("planner.top-three-finger.contact_band_m", "-0.001"),
    ("tactile.pybullet-taxels.dead_taxel_probability", "1.5"),
    ("estimator.mirror-only.prior_b_theta_rad", "-1"),
    ("estimator.mirror-only.prior_m_r_m", "0"),
    ("world.analytic.pitch_m", "0"),
    ("world.analytic.rows", "-1"),
    ("world.analytic.hand_urdf", '"no-such-hand.urdf"'),
    ("world.analytic.hand_urdf", '"sdh2.urdf"'),  # not a parallel gripper
    ("world.analytic.pitch_m", "0.05"),  # no taxel fits the 22 mm wide pad
]


@pytest.mark.parametrize(("key", "value"), BAD_VALUES)
def test_a_nonsense_value_is_refused_naming_its_key(registry, key, value):
    stage, implementation, _ = key.split(".")
    with pytest.raises(ConfigError) as error:
        build_stages(registry, [f"{stage}.use={implementation}", f"{key}={value}"])
    assert f"config key '{key}'" in str(error.value)


@pytest.mark.parametrize(
    "key",
    [
        "planner.top-parallel.palm_to_pad_centre_m",
        "planner.top-parallel.housing_depth_m",
        "world.analytic.max_aperture_m",
    ],
)
def test_a_setting_the_hands_urdf_now_gives_is_refused_naming_its_key(registry, key):
    stage, implementation, _ = key.split(".")
    with pytest.raises(ConfigError, match=f"'{key}'"):
        build_stages(registry, [f"{stage}.use={implementation}", f"{key}=0.1"])


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("far_m=0.4", r"'sensor.pybullet-kinect.min_range_m' \(0.5\) must be < far_m \(0.4\)"),
        ("near_m=4.5", r"'sensor.pybullet-kinect.near_m' \(4.5\) must be < max_range_m \(4.0\)"),
    ],
)
def test_the_depth_range_must_overlap_what_the_renderer_sees(registry, override, message):
    with pytest.raises(ConfigError, match=message):
        build_stages(registry, [f"sensor.pybullet-kinect.{override}"])


@pytest.mark.parametrize(
    ("stage", "implementation"),
    [(stage, name) for stage in STAGES for name in registry_with(AnalyticWorld).names(stage)],
)
def test_every_implementations_defaults_are_within_its_bounds(registry, stage, implementation):
    build_stages(registry, [f"{stage}.use={implementation}"])
