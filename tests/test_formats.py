"""File formats: clouds (PLY, PCD, NPY), contacts JSON, result JSON."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.io.formats import (
    contacts_to_json,
    plan_to_json,
    read_cloud,
    read_contacts,
    write_cloud,
    write_json,
)
from pipeline.types import Contacts, GraspPlan

POINTS = np.random.default_rng(0).normal(size=(50, 3))


@pytest.mark.parametrize("suffix", [".ply", ".pcd", ".npy"])
def test_cloud_round_trip(tmp_path, suffix):
    path = write_cloud(tmp_path / f"cloud{suffix}", POINTS)
    cloud = read_cloud(path)
    assert cloud.frame == "robot"
    np.testing.assert_allclose(cloud.points, POINTS, atol=1e-12)


def test_ply_is_the_file_open3d_writes_and_reads_back(tmp_path):
    from pipeline.io.open3d_loader import open3d

    o3d = open3d()
    ours = write_cloud(tmp_path / "ours.ply", POINTS)
    theirs = tmp_path / "theirs.ply"
    assert o3d.io.write_point_cloud(str(theirs), o3d.geometry.PointCloud(
        o3d.utility.Vector3dVector(POINTS)))  # fmt: skip
    assert ours.read_bytes() == theirs.read_bytes().replace(
        b"comment Created by Open3D", b"comment written by symfuse"
    )
    np.testing.assert_array_equal(np.asarray(o3d.io.read_point_cloud(str(ours)).points), POINTS)
    with pytest.raises(InputError, match=r"empty\.ply: a cloud of no points is not written"):
        write_cloud(tmp_path / "empty.ply", np.zeros((0, 3)))


def test_cloud_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.ply: no such file"):
        read_cloud(tmp_path / "nope.ply")
    (tmp_path / "c.xyz").write_text("1 2 3\n")
    with pytest.raises(InputError, match=r"c\.xyz: unknown cloud format '\.xyz'"):
        read_cloud(tmp_path / "c.xyz")
    (tmp_path / "junk.ply").write_text("this is not a ply file")
    with pytest.raises(InputError, match=r"junk\.ply: not a PLY file \(bad first line\)"):
        read_cloud(tmp_path / "junk.ply")
    np.save(tmp_path / "flat.npy", np.zeros((4, 2)))
    with pytest.raises(InputError, match=r"flat\.npy: expected an \(N, 3\) array"):
        read_cloud(tmp_path / "flat.npy")
    bad = POINTS.copy()
    bad[7, 1] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    with pytest.raises(InputError, match=r"nan\.npy: 1 point\(s\) have NaN .* row 7"):
        read_cloud(tmp_path / "nan.npy")
    np.save(tmp_path / "empty.npy", np.zeros((0, 3)))
    with pytest.raises(InputError, match="no points"):
        read_cloud(tmp_path / "empty.npy")


def test_malformed_ply_and_pcd_are_refused_not_filled_with_garbage(tmp_path):
    """open3d returns a cloud of the declared size for these, whatever the body holds."""
    binary = write_cloud(tmp_path / "c.ply", POINTS).read_bytes()
    (tmp_path / "cut.ply").write_bytes(binary[:-5])
    with pytest.raises(InputError, match=r"cut\.ply: the header declares \d+ points \(\d+ bytes\), "
                       r"the file holds \d+ bytes \(truncated\?\)"):  # fmt: skip
        read_cloud(tmp_path / "cut.ply")
    header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    header += "property float z\nend_header\n"
    for body, message in [
        ("0.5 0 0.1\n0.5 0.1 0.1\n", "the header declares 3 points, the file holds 2"),
        ("0.5 0 0.1\n0.5 nan 0.1\n0.4 0 0\n", "point 1 is not a row of 3 finite numbers"),
        ("0.5 0 0.1\n0.5 0.1\n0.4 0 0\n", "point 1 is not a row of 3 finite numbers"),
    ]:
        (tmp_path / "a.ply").write_text(header + body)
        with pytest.raises(InputError, match=message):
            read_cloud(tmp_path / "a.ply")
    pcd = write_cloud(tmp_path / "c.pcd", POINTS).read_bytes()
    (tmp_path / "more.pcd").write_bytes(pcd.replace(b"POINTS ", b"POINTS 9", 1))
    with pytest.raises(InputError, match=r"more\.pcd: PCD POINTS \d+ is not WIDTH x HEIGHT"):
        read_cloud(tmp_path / "more.pcd")


def contacts(n=3):
    return Contacts(
        positions=np.arange(3 * n, dtype=float).reshape(n, 3) / 100,
        normals=np.tile([0.0, 2.0, 0.0], (n, 1)),
        pads=["left"] * n,
        taxel_indices=np.arange(n),
    )


def plan():
    return GraspPlan(
        gripper="pg70",
        status="ok",
        T_robot_hand=np.eye(4),
        pregrasp_height_m=0.1,
        opening_m=0.065,
        closing_direction=np.array([0.0, 1.0, 0.0]),
        predicted_contacts=np.array([[0.0, -0.02, 0.05], [0.0, 0.02, 0.05]]),
    )


def test_contacts_round_trip_with_plan(tmp_path):
    path = write_json(tmp_path / "contacts.json", contacts_to_json([contacts()], [plan()]))
    recorded = read_contacts(path)
    assert len(recorded.contacts) == 1
    got = recorded.contacts[0]
    np.testing.assert_allclose(got.positions, contacts().positions)
    np.testing.assert_allclose(got.normals, np.tile([0.0, 1.0, 0.0], (3, 1)))  # normalised
    assert list(got.pads) == ["left"] * 3
    assert plan_to_json(recorded.plans[0]) == plan_to_json(plan())
    assert plan_to_json(plan())["score"] is None  # the planner gave none
    scored = dataclasses.replace(plan(), score=0.25)
    path = write_json(tmp_path / "scored.json", contacts_to_json([contacts()], [scored]))
    assert read_contacts(path).plans[0].score == 0.25


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"extra": 1}, r"unknown key 'grasps\[0\]\.plan\.extra'"),
        ({"score": 5}, r"grasps\[0\]\.plan\.score must be a number in \[0, 1\] or null"),
        ({"score": "high"}, r"plan\.score must be a number in \[0, 1\]"),
        ({"predicted_contacts": [[1, 2]]}, r"plan\.predicted_contacts\[0\] must be a list of 3"),
        ({"predicted_contacts": "x"}, r"plan\.predicted_contacts must be a list of points"),
        ({"T_robot_hand": (2 * np.eye(4)).tolist()}, r"T_robot_hand's rotation is not orthonormal"),
        ({"closing_direction": [0, 0, 0]}, r"plan\.closing_direction must be a unit vector"),
        ({"opening_m": -0.05}, r"plan\.opening_m must not be negative"),
        ({"pregrasp_height_m": None}, r"plan\.pregrasp_height_m must be a finite number"),
        ({"gripper": ""}, r"plan\.gripper must be a non-empty string"),
        ({"status": "maybe"}, r"plan\.status must be \"ok\" or \"refused\""),
    ],
)
def test_a_recorded_plan_is_checked_key_by_key(tmp_path, change, message):
    document = contacts_to_json([contacts()], [plan()])
    document["grasps"][0]["plan"].update(change)
    path = write_json(tmp_path / "contacts.json", document)
    with pytest.raises(InputError, match=message):
        read_contacts(path)


def test_a_key_given_twice_is_refused(tmp_path):
    text = json.dumps(contacts_to_json([contacts()], [None]))
    path = tmp_path / "contacts.json"
    path.write_text(text[:-1] + ', "units": "mm"}')
    with pytest.raises(InputError, match="the key 'units' appears twice in one object"):
        read_contacts(path)


def test_unit_normals_are_read_bit_for_bit(tmp_path):
    # Normals a simulated pad gives: unit up to rounding, so that dividing by their length
    # again moves some in the last bits (and a replay would fuse differently).
    normals = np.random.default_rng(0).normal(size=(50, 3))
    unit = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    assert np.any(unit / np.linalg.norm(unit, axis=1, keepdims=True) != unit)
    recorded = Contacts(np.zeros((50, 3)), unit, ["left"] * 50, np.arange(50))
    path = write_json(tmp_path / "contacts.json", contacts_to_json([recorded], [None]))
    np.testing.assert_array_equal(read_contacts(path).contacts[0].normals, unit)


def test_minimal_contacts_document(tmp_path):
    path = tmp_path / "c.json"
    taxel = {"position": [0, 0, 0.1], "normal": [1, 0, 0], "pad": "left"}
    path.write_text(json.dumps({"frame": "robot", "units": "m", "grasps": [{"taxels": [taxel]}]}))
    recorded = read_contacts(path)
    assert recorded.plans == (None,)
    assert recorded.contacts[0].taxel_indices.tolist() == [0]


@pytest.mark.parametrize(
    ("document", "message"),
    [
        (
            {"frame": "robot", "units": "inch", "grasps": []},
            r"units must be \"m\" \(metres\) or \"mm\"",
        ),
        ({"frame": "camera", "units": "m", "grasps": []}, r"frame must be \"robot\""),
        ({"frame": "robot", "units": "m", "grasps": []}, "'grasps' must be a non-empty list"),
        ({"frame": "robot", "units": "m", "grasps": [{"taxels": []}]}, r"grasps\[0\]\.taxels"),
        (
            {
                "frame": "robot",
                "units": "m",
                "grasps": [{"taxels": [{"position": [0, 0, 0], "normal": [0, 0, 0], "pad": "l"}]}],
            },
            r"grasps\[0\]\.taxels\[0\]\.normal has zero length",
        ),
        (
            {
                "frame": "robot",
                "units": "m",
                "grasps": [{"taxels": [{"position": [0, 0], "normal": [0, 0, 1], "pad": "l"}]}],
            },
            r"grasps\[0\]\.taxels\[0\]\.position must be a list of 3 numbers",
        ),
    ],
)
def test_contacts_errors_name_file_and_key(tmp_path, document, message):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(document))
    with pytest.raises(InputError, match=rf"bad\.json: .*{message}"):
        read_contacts(path)


def test_contacts_not_json(tmp_path):
    path = tmp_path / "c.json"
    path.write_text("{oops")
    with pytest.raises(InputError, match=r"c\.json: not valid JSON"):
        read_contacts(path)


def test_nan_becomes_null_in_json(tmp_path):
    path = write_json(tmp_path / "r.json", {"a": float("nan"), "b": np.float32(1.5)})
    assert json.loads(path.read_text()) == {"a": None, "b": 1.5}
