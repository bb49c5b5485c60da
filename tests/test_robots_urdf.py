"""The shipped hand URDFs against the datasheet numbers, via yourdfpy and
PyBullet (two independent parsers and forward-kinematics implementations)."""

from __future__ import annotations

import itertools

import numpy as np
import pybullet as pb
import pytest
import yourdfpy

from robots import ROOT

MM = 1e-3
PG70 = ROOT / "pg70.urdf"
SDH2 = ROOT / "sdh2.urdf"
SDH_FINGERS = ("f1", "f2", "thumb")


@pytest.fixture(scope="module")
def pg70() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(PG70))


@pytest.fixture(scope="module")
def sdh2() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(SDH2))


def _box(robot: yourdfpy.URDF, link: str) -> np.ndarray:
    """Size of a link's (first) collision box."""
    return np.asarray(robot.link_map[link].collisions[0].geometry.box.size)


def _pose(robot: yourdfpy.URDF, link: str, cfg: dict[str, float]) -> np.ndarray:
    robot.update_cfg(cfg)
    return robot.get_transform(link, "palm")


# ---------------------------------------------------------------- PG-70


def test_pg70_aperture_range_is_0_to_65_mm_between_pad_surfaces(pg70):
    lower = {"left_jaw": 0.0, "right_jaw": 0.0}
    upper = {j: pg70.joint_map[j].limit.upper for j in lower}
    for j in lower:
        assert pg70.joint_map[j].limit.lower == pytest.approx(0.0)
    for cfg, expected in ((lower, 0.0), (upper, 65 * MM)):
        left = _pose(pg70, "left_pad", cfg)[:3, 3]
        right = _pose(pg70, "right_pad", cfg)[:3, 3]
        assert np.linalg.norm(right - left) == pytest.approx(expected, abs=1e-6)


def test_pg70_pads_face_each_other_along_x_with_rows_toward_the_fingertips(pg70):
    cfg = {"left_jaw": 0.02, "right_jaw": 0.02}
    left = _pose(pg70, "left_pad", cfg)
    right = _pose(pg70, "right_pad", cfg)
    np.testing.assert_allclose(left[:3, 2], [1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(right[:3, 2], [-1, 0, 0], atol=1e-6)
    for pad in (left, right):
        np.testing.assert_allclose(pad[:3, 0], [0, 0, 1], atol=1e-6)
        assert np.linalg.det(pad[:3, :3]) == pytest.approx(1.0)


def test_pg70_pad_and_housing_sizes(pg70):
    # Pad about 22 x 50 mm, holding a 6 x 14 grid at 3.4 mm (20.4 x 47.6 mm active).
    along, across, _ = _box(pg70, "left_pad")
    assert across == pytest.approx(22 * MM) and along == pytest.approx(50 * MM)
    assert across >= 6 * 3.4 * MM and along >= 14 * 3.4 * MM
    assert sorted(_box(pg70, "palm")) == pytest.approx(sorted([80 * MM, 112 * MM, 78 * MM]))
    jaw = pg70.joint_map["left_jaw"].origin
    assert jaw[2, 3] == pytest.approx(79 * MM)


# ---------------------------------------------------------------- SDH-2


def test_sdh2_finger_bases_form_the_66_mm_triangle_at_74_5_mm(sdh2):
    expected = {"f1": (19.05, 33.0), "f2": (19.05, -33.0), "thumb": (-38.11, 0.0)}
    bases = {f: _pose(sdh2, f"{f}_knuckle", {})[:3, 3] for f in SDH_FINGERS}
    for finger, (x_mm, y_mm) in expected.items():
        np.testing.assert_allclose(bases[finger], np.array([x_mm, y_mm, 74.5]) * MM, atol=1e-6)
    for a, b in itertools.combinations(SDH_FINGERS, 2):
        assert np.linalg.norm(bases[a] - bases[b]) == pytest.approx(66 * MM, abs=0.05 * MM)


def _closing_direction(robot: yourdfpy.URDF, finger: str, spread_rad: float) -> np.ndarray:
    return _pose(robot, f"{finger}_proximal", {"f1_base": spread_rad})[:3, 0]


def test_sdh2_spread_couples_f1_f2_in_opposite_directions_and_60_deg_gives_120_deg(sdh2):
    assert sdh2.joint_map["f2_base"].mimic.joint == "f1_base"
    for j in ("f1_base", "f2_base"):
        assert sdh2.joint_map[j].limit.lower == pytest.approx(0.0)
        assert sdh2.joint_map[j].limit.upper == pytest.approx(np.pi / 2, abs=1e-6)
    assert sdh2.joint_map["thumb_base"].type == "fixed"
    # At 0 deg f1 and f2 face the thumb.
    np.testing.assert_allclose(_closing_direction(sdh2, "f1", 0.0), [-1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(_closing_direction(sdh2, "f2", 0.0), [-1, 0, 0], atol=1e-6)
    # Opposite rotations: f1 turns counter-clockwise, f2 clockwise, thumb not at all.
    f1 = _closing_direction(sdh2, "f1", 0.3)
    f2 = _closing_direction(sdh2, "f2", 0.3)
    assert np.arctan2(f1[1], f1[0]) == pytest.approx(np.pi + 0.3 - 2 * np.pi)
    assert np.arctan2(f2[1], f2[0]) == pytest.approx(np.pi - 0.3)
    np.testing.assert_allclose(_closing_direction(sdh2, "thumb", 0.3), [1, 0, 0], atol=1e-6)
    # At 60 deg the three fingers are 120 deg apart and face the palm axis.
    spread = np.deg2rad(60.0)
    for a, b in itertools.combinations(SDH_FINGERS, 2):
        da, db = _closing_direction(sdh2, a, spread), _closing_direction(sdh2, b, spread)
        assert np.degrees(np.arccos(np.clip(da @ db, -1, 1))) == pytest.approx(120.0, abs=0.05)
    for finger in SDH_FINGERS:
        base = _pose(sdh2, f"{finger}_knuckle", {"f1_base": spread})[:2, 3]
        direction = _closing_direction(sdh2, finger, spread)[:2]
        assert base[0] * direction[1] - base[1] * direction[0] == pytest.approx(0.0, abs=1e-4)
        assert base @ direction < 0.0


def test_sdh2_link_lengths_and_joint_ranges(sdh2):
    for finger in SDH_FINGERS:
        knuckle = _pose(sdh2, f"{finger}_knuckle", {})
        proximal = _pose(sdh2, f"{finger}_proximal", {})
        distal = _pose(sdh2, f"{finger}_distal", {})
        # First bending joint 16.5 mm above the base, proximal link 86.5 mm.
        assert np.linalg.norm(proximal[:3, 3] - knuckle[:3, 3]) == pytest.approx(16.5 * MM)
        assert np.linalg.norm(distal[:3, 3] - proximal[:3, 3]) == pytest.approx(86.5 * MM)
        # Distal link reaches 68.5 mm to the tip.
        tips = [
            c.origin[2, 3] + c.geometry.box.size[2] / 2
            for c in sdh2.link_map[f"{finger}_distal"].collisions
        ]
        assert max(tips) == pytest.approx(68.5 * MM)
        for part in ("proximal", "distal"):
            limit = sdh2.joint_map[f"{finger}_{part}"].limit
            assert (limit.lower, limit.upper) == pytest.approx((-np.pi / 2, np.pi / 2), abs=1e-6)


def test_sdh2_pads_sit_on_the_inner_side_at_the_datasheet_offsets(sdh2):
    for finger in SDH_FINGERS:
        for part, offset_mm, centre_mm in (("proximal", 15.4, 43.7), ("distal", 14.8, 42.0)):
            link = _pose(sdh2, f"{finger}_{part}", {"f1_base": 0.7, f"{finger}_proximal": 0.4})
            pad = _pose(sdh2, f"{finger}_{part}_pad", {"f1_base": 0.7, f"{finger}_proximal": 0.4})
            T_link_pad = np.linalg.inv(link) @ pad
            np.testing.assert_allclose(
                T_link_pad[:3, 3], [offset_mm * MM, 0, centre_mm * MM], atol=1e-9
            )
            np.testing.assert_allclose(T_link_pad[:3, 2], [1, 0, 0], atol=1e-6)  # normal inward
            np.testing.assert_allclose(T_link_pad[:3, 0], [0, 0, 1], atol=1e-6)  # rows to tip


# ---------------------------------------------------------------- PyBullet agrees


@pytest.mark.parametrize(
    ("path", "pads"),
    [
        (PG70, ["left_pad", "right_pad"]),
        (SDH2, [f"{f}_{p}_pad" for f in SDH_FINGERS for p in ("proximal", "distal")]),
    ],
)
def test_pybullet_loads_the_urdf_and_its_kinematics_match_yourdfpy(path, pads):
    robot = yourdfpy.URDF.load(str(path))
    client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(
            str(path),
            useFixedBase=True,
            flags=pb.URDF_USE_INERTIA_FROM_FILE,
            physicsClientId=client,
        )
        joints, links = {}, {}
        for index in range(pb.getNumJoints(body, physicsClientId=client)):
            info = pb.getJointInfo(body, index, physicsClientId=client)
            links[info[12].decode()] = index
            if info[2] != pb.JOINT_FIXED:
                name = info[1].decode()
                joints[name] = index
                limit = robot.joint_map[name].limit
                assert (info[8], info[9]) == pytest.approx((limit.lower, limit.upper))
        assert set(joints) == {n for n, j in robot.joint_map.items() if j.type != "fixed"}
        for link in robot.link_map:
            if link != "palm":
                assert robot.link_map[link].inertial.mass > 0.0
        rng = np.random.default_rng(3)
        for _ in range(3):
            cfg = {}
            for name in robot.actuated_joint_names:
                limit = robot.joint_map[name].limit
                cfg[name] = rng.uniform(limit.lower, limit.upper)
            if "f1_base" in cfg:  # the mimic joint: symfuse's Hand drives it like f1_base
                cfg["f2_base"] = cfg["f1_base"]
            for name, index in joints.items():
                pb.resetJointState(body, index, cfg[name], physicsClientId=client)
            robot.update_cfg({n: cfg[n] for n in robot.actuated_joint_names})
            for pad in pads:
                state = pb.getLinkState(
                    body, links[pad], computeForwardKinematics=True, physicsClientId=client
                )
                rotation = np.array(pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)
                expected = robot.get_transform(pad, "palm")
                np.testing.assert_allclose(state[4], expected[:3, 3], atol=1e-6)
                np.testing.assert_allclose(rotation, expected[:3, :3], atol=1e-6)
    finally:
        pb.disconnect(client)
