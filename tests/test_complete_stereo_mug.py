"""`symfuse complete` on a simulated stereo view of the catalogue cup with its handle in view:
VC alone mirrors the body about a plane near the handle's root (a second handle); complete's
default, VC choosing the kind by evidence, puts the handle in the plane."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.catalogue.objects import load_object
from pipeline.cli import main
from pipeline.config import load_config
from pipeline.io.camera_file import camera_to_json
from pipeline.registry import load_registry
from pipeline.symmetry.truth_file import true_symmetries
from pipeline.types import SceneSetup


def stereo_capture(folder, yaw_deg: float, seed: int):
    """The stereo camera's view of the cup at ``yaw_deg`` as depth.npy and camera.json (in
    the world's frame), and the cup's true mirror plane's normal there."""
    registry = load_registry()
    config = load_config(registry, overrides=['sensor.use="pybullet-stereo"'])
    cup = load_object("cup")
    world = config.create(registry, "world")
    try:
        world.load_scene(SceneSetup(cup, 0.0, 0.0, float(np.radians(yaw_deg)), seed))
        T = world.object_pose().transform
        observation = config.create(registry, "sensor").observe(world)
    finally:
        world.close()
    np.save(folder / "depth.npy", observation.depth_m)
    (folder / "camera.json").write_text(json.dumps(camera_to_json(observation)))
    (plane,) = [s.transformed(T) for s in true_symmetries(cup) if s.is_plane]
    return folder / "depth.npy", plane.direction


@pytest.mark.slow
@pytest.mark.parametrize("yaw_deg", [99.0, -99.0])
def test_the_stereo_mug_gets_its_handle_in_the_plane(tmp_path, yaw_deg):
    capture, true_normal = stereo_capture(tmp_path, yaw_deg, seed=3)
    out = tmp_path / "out"
    assert main(["complete", str(capture), "--out", str(out)]) == 0
    (cup,) = json.loads((out / "objects.json").read_text())["objects"]
    normal = np.array([*cup["plane"]["normal"], 0.0])
    angle = np.degrees(np.arccos(min(1.0, abs(normal @ true_normal))))
    assert cup["status"] == "completed" and angle < 5.0
