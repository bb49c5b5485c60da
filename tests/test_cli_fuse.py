"""`symfuse fuse` on recorded files: outputs, exit codes, one-line errors."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from pipeline.io.formats import contacts_to_json, read_cloud, write_cloud, write_json
from pipeline.metrics import fit_circle_taubin
from pipeline.synthetic import make_case


def test_fuse_writes_results_and_improves_the_diameter(recording, tmp_path, run):
    folder, case, plane = recording
    code, out, err = run(
        "fuse",
        "--cloud",
        folder / "cloud.ply",
        "--contacts",
        folder / "contacts.json",
        f"--plane={plane}",
        "--out",
        tmp_path,
    )
    assert code == 0, err
    document = json.loads((tmp_path / "result.json").read_text())
    assert [s["stage"] for s in document["stages"]] == [0, 1, 2]
    for stage in document["stages"]:
        assert set(stage) >= {"plane", "bias", "status", "iterations", "seconds"}
        assert set(stage["plane"]) >= {"normal", "offset"}
        assert set(stage["bias"]) >= {"yaw", "translation"}
    assert document["stages"][2]["status"] in ("converged", "max_iterations")
    assert document["config"]["estimator"]["use"] == "iekf"
    true_diameter = 2 * case.cylinder.radius_m
    errors = [
        abs(
            fit_circle_taubin(read_cloud(tmp_path / f"completed_stage{i}.ply").points).diameter_m
            - true_diameter
        )
        for i in range(3)
    ]
    assert errors[2] < 0.004 < errors[0]
    assert "stage" in out and "wrote" in out
    # A bare cloud has no depth image: only the taxel check runs, and says so.
    for stage in document["stages"]:
        consistency = stage["consistency"]
        assert consistency["checks"] == ["taxels"]
        assert consistency["free_space_violations"] is None
        assert set(consistency) >= {"taxel_rms_mm", "nis", "nis_threshold", "consistent"}
    final = document["stages"][2]["consistency"]
    assert final["consistent"] and final["taxel_rms_mm"] < 2.0
    assert document["selected_stage"] == 2 and document["selection_reason"]
    assert "consistent" in out and "selected: Stage 2" in out
    assert document["one_sided_grasps"] == [] and "note:" not in out


def test_fuse_names_a_grasp_whose_taxels_touch_one_side_only(recording, tmp_path, run):
    folder, case, plane = recording
    contacts = case.contacts
    one_pad = contacts.select(contacts.pads == contacts.pads[0])
    path = write_json(tmp_path / "one-sided.json", contacts_to_json([contacts, one_pad]))
    out_dir = tmp_path / "out"
    code, out, err = run(
        "fuse", "--cloud", folder / "cloud.ply", "--contacts", path, f"--plane={plane}",
        "--out", out_dir,
    )  # fmt: skip
    assert code in (0, 3), err
    assert json.loads((out_dir / "result.json").read_text())["one_sided_grasps"] == [2]
    assert "note: grasp 2 touched one side only or nothing: " in out


def test_npy_cloud_gives_the_same_estimate(recording, tmp_path, run):
    folder, _, plane = recording
    for suffix, out in ((".ply", tmp_path / "a"), (".npy", tmp_path / "b")):
        code, _, err = run(
            "fuse",
            "--cloud",
            folder / f"cloud{suffix}",
            "--contacts",
            folder / "contacts.json",
            f"--plane={plane}",
            "--out",
            out,
        )
        assert code == 0, err
    a = json.loads((tmp_path / "a" / "result.json").read_text())["stages"][2]
    b = json.loads((tmp_path / "b" / "result.json").read_text())["stages"][2]
    assert a["plane"]["normal"] == pytest.approx(b["plane"]["normal"])
    assert a["plane"]["offset"] == pytest.approx(b["plane"]["offset"])


@pytest.mark.parametrize(
    ("schedule", "status"), [("standard", "no_correspondence"), ("hybrid", "diverged")]
)
@pytest.mark.slow
def test_failed_estimate_still_writes_result_and_exits_3(
    recording, tmp_path, run, schedule, status
):
    """Taxels 5 m from the object: eq. 9 finds no correspondence; eq. 13 (hybrid's start)
    always finds some, by design, and the estimate runs away."""
    folder, case, plane = recording
    far = case.contacts.positions + np.array([5.0, 0.0, 0.0])
    moved = type(case.contacts)(
        far, case.contacts.normals, case.contacts.pads, case.contacts.taxel_indices
    )
    write_json(tmp_path / "far.json", contacts_to_json([moved]))
    code, _, err = run(
        "fuse",
        "--cloud",
        folder / "cloud.ply",
        "--contacts",
        tmp_path / "far.json",
        f"--plane={plane}",
        "--set",
        f"estimator.iekf.schedule={schedule}",
        "--set",
        "estimator.iekf.max_iterations=5",  # it fails within a few iterations either way
        "--out",
        tmp_path / "out",
    )
    assert code == 3
    assert err.strip().splitlines() == [
        f"symfuse: error: estimate {status} (see {tmp_path / 'out'}/result.json)"
    ]
    document = json.loads((tmp_path / "out" / "result.json").read_text())
    assert document["status"] == status
    assert (tmp_path / "out" / "completed_stage2.ply").exists()


def test_initialiser_by_name_and_one_that_needs_a_depth_image(recording, tmp_path, run):
    folder, _, _ = recording
    code, _, err = run(
        "fuse",
        "--cloud",
        folder / "cloud.ply",
        "--contacts",
        folder / "contacts.json",
        "--init",
        "pca",
        "--out",
        tmp_path / "pca",
    )
    assert code == 0, err
    code, _, err = run(
        "fuse",
        "--cloud",
        folder / "cloud.ply",
        "--contacts",
        folder / "contacts.json",
        "--init",
        "vc",
        "--out",
        tmp_path / "vc",
    )
    assert code == 2
    assert err.startswith(
        "symfuse: error: initialiser 'vc' needs the depth image the cloud came from; give --depth"
    )
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "vc").exists()  # bad config: nothing left behind


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda d: d / "missing.ply", r"missing\.ply: no such file"),
        (lambda d: (np.save(d / "e.npy", np.zeros((0, 3))), d / "e.npy")[1], "has no points"),
        (lambda d: (np.save(d / "1.npy", np.ones((1, 3))), d / "1.npy")[1], "a single point"),
        (
            lambda d: (np.save(d / "n.npy", np.full((3, 3), np.inf)), d / "n.npy")[1],
            "NaN or infinite",
        ),
    ],
)
def test_bad_cloud_is_one_line_exit_2(recording, tmp_path, run, make, message):
    folder, _, plane = recording
    code, _, err = run(
        "fuse",
        "--cloud",
        make(tmp_path),
        "--contacts",
        folder / "contacts.json",
        f"--plane={plane}",
        "--out",
        tmp_path / "out",
    )
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert err.startswith("symfuse: error: ")
    assert __import__("re").search(message, err)


@pytest.mark.parametrize(
    ("document", "message"),
    [
        ({"frame": "robot", "units": "inch", "grasps": []}, 'units must be "m" (metres) or "mm"'),
        ({"frame": "robot", "units": "m", "grasps": []}, "'grasps' must be a non-empty list"),
        (
            {
                "frame": "robot",
                "units": "m",
                "grasps": [
                    {"taxels": [{"position": [0, 0, 0], "normal": [0, 0, 0], "pad": "left"}]}
                ],
            },
            "normal has zero length",
        ),
    ],
)
def test_bad_contacts_is_one_line_exit_2(recording, tmp_path, run, document, message):
    folder, _, plane = recording
    (tmp_path / "c.json").write_text(json.dumps(document))
    code, _, err = run(
        "fuse",
        "--cloud",
        folder / "cloud.ply",
        "--contacts",
        tmp_path / "c.json",
        f"--plane={plane}",
        "--out",
        tmp_path / "out",
    )
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert message in err


def test_bad_plane_and_bad_override(recording, tmp_path, run):
    folder, _, _ = recording
    base = [
        "fuse",
        "--cloud",
        folder / "cloud.ply",
        "--contacts",
        folder / "contacts.json",
        "--out",
        tmp_path,
    ]
    for plane, message in [
        ("0,0,1", "the normal (NX, NY) must be non-zero"),
        ("1,0", "expected three numbers NX,NY,D, got 2"),
        ("1,0,0,4", "expected three numbers NX,NY,D, got 4"),
        ("1,x,0", "expected three numbers NX,NY,D"),
        ("nan,0,0", "NX, NY and D must be finite"),
        ("1,0,1e300", "the plane passes 1e+300 m from the robot base, beyond any tabletop"),
        ("0.001,0,0.05", "the plane passes 50 m from the robot base"),
    ]:
        code, _, err = run(*base, "--plane", plane)
        assert code == 2
        assert err.startswith(f"symfuse: error: --plane '{plane}': {message}")
        assert len(err.strip().splitlines()) == 1
    code, _, err = run(*base, "--plane", "1,0,0", "--set", "estimator.iekf.bogus=1")
    assert code == 2
    assert err.startswith("symfuse: error: unknown config key 'estimator.iekf.bogus'")


def test_contacts_of_another_object_exit_3_as_inconsistent(tmp_path, run):
    """Three pads that touched the same cylinder scaled 1.4x: results written, exit 3."""
    case = make_case(np.random.default_rng(3), gripper="three_finger")
    big = make_case(
        np.random.default_rng(3),
        gripper="three_finger",
        cylinder=dataclasses.replace(case.cylinder, radius_m=1.4 * case.cylinder.radius_m),
    )
    write_cloud(tmp_path / "cloud.ply", case.cloud.points)
    write_json(tmp_path / "contacts.json", contacts_to_json([big.contacts]))
    plane = case.init_plane
    text = ",".join(repr(float(v)) for v in (*plane.normal[:2], plane.offset_m))
    code, out, err = run(
        "fuse",
        "--cloud",
        tmp_path / "cloud.ply",
        "--contacts",
        tmp_path / "contacts.json",
        f"--plane={text}",
        "--out",
        tmp_path / "out",
    )
    assert code == 3
    assert err.strip() == (
        f"symfuse: error: estimate inconsistent (see {tmp_path / 'out'}/result.json)"
    )
    document = json.loads((tmp_path / "out" / "result.json").read_text())
    assert document["status"] == "inconsistent"
    assert not document["stages"][2]["consistency"]["consistent"]
    assert "taxels" in document["stages"][2]["consistency"]["reason"]
    assert "NO" in out


def test_a_depth_image_needs_its_camera_placed_in_the_robot_frame(recording, tmp_path, run):
    folder, _, plane = recording
    np.save(tmp_path / "depth.npy", np.full((4, 6), 0.8, dtype=np.float32))
    intrinsics = {"width": 6, "height": 4, "fx": 5.0, "fy": 5.0, "cx": 2.5, "cy": 1.5}
    write_json(tmp_path / "camera.json", {"intrinsics": intrinsics})
    common = ["fuse", "--cloud", folder / "cloud.ply", "--contacts", folder / "contacts.json",
              f"--plane={plane}"]  # fmt: skip
    code, _, err = run(*common, "--depth", tmp_path / "depth.npy", "--out", tmp_path / "a")
    assert code == 2
    assert err.strip() == (
        f"symfuse: error: {tmp_path / 'camera.json'}: no T_robot_camera: the cloud and the "
        "contacts are in the robot frame, so the depth image's camera must be placed in it"
    )
    assert not (tmp_path / "a").exists()
    code, _, err = run(*common, "--camera", tmp_path / "camera.json", "--out", tmp_path / "b")
    assert code == 2
    assert err.strip() == (
        "symfuse: error: --camera describes the camera of --depth, which is not given"
    )
