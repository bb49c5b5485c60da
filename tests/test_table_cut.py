"""The table cut follows the measured table: low objects are segmented, down to the table.

The fitted table (:func:`measure_table`) is checked against planes of known tilt and
noise drawn here; the default trial's segmenter and sensor then see a 12 mm box and a
14 mm slab in PyBullet: each must be segmented with its five lowest points within 5 mm
of the table and no table point taken along (the simulator's object mask says which is
which).
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pipeline.catalogue.objects import load_object
from pipeline.config import load_config
from pipeline.perception.table import measure_table, table_from_height
from pipeline.registry import load_registry
from plugins.worlds.pybullet_world import Pybullet


def test_measure_table_recovers_tilt_and_range_dependent_noise():
    rng = np.random.default_rng(4)
    xy = rng.uniform(-1.0, 1.0, size=(40000, 2))
    viewpoint = np.array([-1.5, 0.0, 1.0])
    distance = np.linalg.norm(np.column_stack([xy, np.zeros(len(xy))]) - viewpoint, axis=1)
    sigma = 0.001 * distance**2  # noise growing with range, as a triangulating sensor's
    tilt = np.deg2rad(0.3)  # a calibration error the known height does not know of
    z = np.tan(tilt) * xy[:, 0] + 0.002 + rng.normal(0.0, sigma)
    fit = measure_table(np.column_stack([xy, z]), viewpoint, table_from_height(0.0), 0.005)
    normal = np.array([-np.sin(tilt), 0.0, np.cos(tilt)])
    assert np.degrees(np.arccos(fit.plane.normal @ normal)) < 0.02
    assert fit.plane.offset_m == pytest.approx(0.002 * np.cos(tilt), abs=1e-4)
    for r in (1.4, 1.9, 2.4):  # within the table's distances, 1.1-2.9 m
        assert fit.sigma_at(np.array([r]))[0] == pytest.approx(0.001 * r**2, rel=0.15)
    # The table's height under an object: the tilted plane's z there, as generated.
    assert fit.plane.z_at(np.array([0.5, -0.3])) == pytest.approx(
        np.tan(tilt) * 0.5 + 0.002, abs=1e-4
    )


def test_measure_table_names_a_missing_table():
    points = np.column_stack([np.zeros(100), np.zeros(100), np.linspace(0.1, 0.2, 100)])
    with pytest.raises(ValueError, match=r"points lie within 5\.0 mm of the table"):
        measure_table(points, np.array([0.0, 0.0, 1.0]), table_from_height(0.0), 0.005)


@pytest.mark.parametrize("extents", [(0.06, 0.05, 0.012), (0.12, 0.08, 0.014)])
def test_default_segmenter_keeps_a_low_object_down_to_the_table(tmp_path, extents):
    registry = load_registry()
    config = load_config(registry)
    path = tmp_path / "low.stl"
    trimesh.creation.box(extents).export(path)
    obj = load_object(path)
    with Pybullet.create(obj, None, x=0.0, y=0.0, yaw=0.5, seed=3) as world:
        observation = config.create(registry, "sensor").observe(world)
    cloud = config.create(registry, "segmenter").segment(observation)
    on_object = observation.object_mask[cloud.pixels[:, 0], cloud.pixels[:, 1]]
    assert on_object.sum() >= 0.8 * observation.object_mask.sum()
    assert (~on_object).sum() <= 0.01 * len(cloud.points)  # the table stays out
    lowest = np.sort(cloud.points[:, 2] - observation.table_height_m)[:5]
    assert lowest.max() < 0.005
