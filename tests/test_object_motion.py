"""How a grasp moved the object: shift, turn about the vertical and tilt, on hand-made
poses (rotations built with scipy)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from pipeline.metrics.evaluation import object_motion, object_turn
from pipeline.types import ObjectPose


def _pose(position_m, rotation: Rotation) -> ObjectPose:
    return ObjectPose(np.asarray(position_m, float), rotation.as_quat())


@pytest.mark.parametrize(("start_deg", "turn_deg"), [(0.0, 30.0), (105.0, -6.5), (170.0, 40.0)])
def test_a_turn_about_the_vertical_is_reported_and_does_not_tilt(start_deg, turn_deg):
    before = _pose([0.5, 0.0, 0.0], Rotation.from_euler("z", start_deg, degrees=True))
    after = _pose([0.5, 0.0, 0.0], Rotation.from_euler("z", start_deg + turn_deg, degrees=True))
    assert np.degrees(object_turn(before, after)) == pytest.approx(turn_deg)
    box = trimesh.creation.box((0.04, 0.06, 0.1))
    shift, tilt = object_motion(box, before, after)
    assert shift == pytest.approx(0.0, abs=1e-12) and tilt == pytest.approx(0.0, abs=1e-7)


def test_a_tilt_is_not_a_turn():
    before = _pose([0.0, 0.0, 0.0], Rotation.identity())
    after = _pose([0.0, 0.0, 0.0], Rotation.from_euler("x", 10.0, degrees=True))
    assert object_turn(before, after) == pytest.approx(0.0, abs=1e-12)
    _, tilt = object_motion(trimesh.creation.box((0.04, 0.06, 0.1)), before, after)
    assert np.degrees(tilt) == pytest.approx(10.0)
