"""The wide gripper's URDF reads as the numbers it was written with, and a trial runs
with it and its planner in symfuse's analytic world (no physics)."""

from __future__ import annotations

import pytest
from symfuse_wide_gripper import URDF, WideParallel, WidePybullet

from pipeline.api.io import read_hand_geometry


def test_the_urdf_reads_as_its_numbers():
    g = read_hand_geometry(URDF)
    assert g.fingers == ("left", "right")
    left, right = g.pad("left"), g.pad("right")
    # Jaw joints 50 mm below the flange, pads 70 mm down the jaws, 5 mm off the axis.
    assert left.centre_m == pytest.approx((-0.005, 0.0, 0.05 + 0.07))
    assert right.centre_m == pytest.approx((0.005, 0.0, 0.05 + 0.07))
    assert left.normal == pytest.approx((1.0, 0.0, 0.0))
    assert (left.length_m, left.width_m) == pytest.approx((0.03, 0.03))
    # The 90 mm finger box ends 20 mm below the pad's centre; its face stands at
    # 12 - 5 = 7 mm from the axis, 2 mm behind the pad's surface at 5 mm.
    assert left.centre_to_fingertip_m == pytest.approx(0.09 - 0.07)
    assert left.recess_m == pytest.approx(0.002)
    assert g.fingertip_depth_m == pytest.approx(0.05 + 0.09)
    assert g.jaw_travel_m == pytest.approx(0.01 + 2 * 0.05)
    assert g.housing.depth_m == pytest.approx(0.05)
    assert (g.housing.half_length_m, g.housing.half_width_m) == pytest.approx((0.08, 0.03))


def test_the_world_offers_it_and_the_planner_names_it():
    assert "wide" in WidePybullet.hands and {"pg70", "sdh"} <= set(WidePybullet.hands)
    assert WideParallel.grippers == ("wide",)


def test_a_trial_with_it_in_the_analytic_world(tmp_path):
    out_dir = tmp_path / "trial"
    # --8<-- [start:analytic]
    from pipeline.testing import AnalyticWorld, load_config, registry_with, run_trial

    registry = registry_with(AnalyticWorld, WideParallel)
    config = load_config(
        registry,
        overrides=[
            "world.use=analytic",
            f'world.analytic.hand_urdf="{URDF}"',
            "trial.gripper=parallel",
            "planner.use=wide-parallel",
        ],
    )
    record = run_trial(config, registry, out_dir)
    # --8<-- [end:analytic]
    assert record.document["stages_used"]["planner"] == "wide-parallel"
    # Both pads pressed the box.
    assert set(record.document["grasps"][0]["pads_in_contact"]) == {"left", "right"}
    assert record.document["taxels_in_contact"] > 0
