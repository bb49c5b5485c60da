"""Real scans through whole trials: non-watertight YCB meshes with an arbitrary origin.

Needs a folder of YCB scans named by ``$SYMFUSE_SCANS`` (skipped cleanly when unset); slow
(one full trial per case).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from pipeline.experiments.paper_trial import run_paper_trial
from pipeline.experiments.scanned import SCANS_ENV, default_scans_dir, scan_trial_params

YCB_ROOT = default_scans_dir()

pytestmark = [
    pytest.mark.slow,
    pytest.mark.ycb,
    pytest.mark.skipif(
        YCB_ROOT is None or not YCB_ROOT.is_dir(), reason=f"no YCB scans: set {SCANS_ENV}"
    ),
]


@pytest.mark.parametrize(
    ("scan", "gripper"), [("004_sugar_box", "pg70"), ("006_mustard_bottle", "sdh")]
)
def test_a_scan_goes_through_a_whole_trial(scan, gripper, tmp_path):
    path = YCB_ROOT / scan / "textured.obj"
    if not path.is_file():
        pytest.skip(f"{path} not found")
    source = trimesh.load(path, force="mesh")
    assert not source.is_watertight
    assert np.linalg.norm(source.bounds.mean(axis=0)[:2]) > 0.005  # origin off the centre

    params = scan_trial_params(path, seed=1, trial_dir=tmp_path)
    assert params["gripper"] == "auto"
    row = run_paper_trial(params)

    assert row["failed"] is None
    assert row["gripper"] == gripper  # the hand with the best feasible grasp
    assert row["points"] > 500
    assert row["taxels_in_contact"] > 0
    document = json.loads((tmp_path / "result.json").read_text())
    assert [stage["stage"] for stage in document["stages"]] == [0, 1, 2]
    mesh = trimesh.load(tmp_path / "object_final.ply", force="mesh")
    for k in (0, 2):
        completed = np.asarray(trimesh.load(tmp_path / f"completed_stage{k}.ply").vertices)
        assert np.all(np.isfinite(completed))
        # independent oracle for the deviation: trimesh closest points on every 20th point
        _, distances, _ = trimesh.proximity.closest_point(mesh, completed[::20])
        assert row[f"stage{k}_deviation_median_mm"] == pytest.approx(
            1e3 * np.median(distances), abs=1.0
        )
    # the completed model lies on the object, not somewhere else in the scene
    assert row["stage2_deviation_median_mm"] < 20.0
