"""The ``pybullet-taxels`` tactile model against analytic contact sets and grasp physics."""

from __future__ import annotations

from collections.abc import Iterator
from types import SimpleNamespace

import numpy as np
import pybullet as pb
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError
from pipeline.registry import StageRegistry
from pipeline.sim.grasping import execute_grasp
from pipeline.sim.hands import Hand
from pipeline.types import GraspPlan
from plugins.tactile import pybullet_taxels
from plugins.tactile.pybullet_taxels import PybulletTaxels

MM = 1e-3
PITCH = 3.4 * MM
PAD_CENTRE_DEPTH = 0.125  # PG-70 pad centres below the palm (robots/pg70.urdf)


@pytest.fixture
def client() -> Iterator[int]:
    client = pb.connect(pb.DIRECT)
    yield client
    pb.disconnect(client)


def _top_down(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [x, y, z]
    return T


def _world(client: int, hand: Hand, object_id: int, seed: int = 0) -> SimpleNamespace:
    """The part of the World contract a tactile model uses, over a bare PyBullet scene."""
    return SimpleNamespace(
        taxels=lambda behind_m, beyond_m: hand.taxel_state(object_id, behind_m, beyond_m),
        rng=np.random.default_rng(seed),
    )


def test_registers_and_validates_its_parameters():
    registry = StageRegistry()
    pybullet_taxels.symfuse_register_stages(registry=registry)
    assert registry.names("tactile") == ["pybullet-taxels"]
    model = registry.create("tactile", "pybullet-taxels", {"contact_threshold_m": 0.002})
    assert model.params.contact_threshold_m == 0.002
    with pytest.raises(ConfigError, match=r"tactile\.pybullet-taxels\.ray_length_m"):
        registry.create("tactile", "pybullet-taxels", {"ray_length_m": 0.0005})
    with pytest.raises(ConfigError, match="dead_taxel_probability"):
        registry.create("tactile", "pybullet-taxels", {"dead_taxel_probability": 1.5})


def test_flat_pads_on_a_cylinder_report_exactly_the_analytic_contact_set(client):
    """Two PG-70 pads 0.2 mm from a fixed vertical cylinder (radius 20 mm): a taxel at
    lateral offset y is in contact when 0.2 mm + r - sqrt(r^2 - y^2) <= 1 mm, and only
    rows beside the cylinder (its top lies between two rows) can touch."""
    radius, clearance, threshold = 0.020, 0.0002, 0.001
    top = 0.0852  # midway between rows 3 and 4 (palm at 200 mm, see row_z below)
    shape = pb.createCollisionShape(
        pb.GEOM_CYLINDER, radius=radius, height=top, physicsClientId=client
    )
    cylinder = pb.createMultiBody(
        0, shape, basePosition=[0.4, 0.0, top / 2], physicsClientId=client
    )
    hand = Hand.load(client, "pg70")
    palm_z = 0.2
    hand.reset_pose(_top_down(0.4, 0.0, palm_z))
    hand.set_opening(2 * (radius + clearance))
    model = PybulletTaxels(PybulletTaxels.Params(contact_threshold_m=threshold))
    contacts = model.read(_world(client, hand, cylinder), None)

    # Pad frames: rows grow toward the fingertip (down), columns across (horizontal).
    rows, cols = np.divmod(np.arange(84), 6)
    row_z = palm_z - PAD_CENTRE_DEPTH - (rows - 6.5) * PITCH
    col_y = (cols - 2.5) * PITCH
    gap = clearance + radius - np.sqrt(np.maximum(radius**2 - col_y**2, 0.0))
    expected = np.flatnonzero((gap <= threshold) & (row_z < top))
    assert np.all(np.abs(row_z - top) > PITCH / 4)  # no taxel row sits on the top edge
    for pad in ("left", "right"):
        got = np.sort(contacts.taxel_indices[contacts.pads == pad])
        np.testing.assert_array_equal(got, expected)
    assert len(contacts) == 2 * len(expected) > 0

    frames = hand.taxel_frames()
    for i in range(len(contacts)):
        match = (frames.pads == contacts.pads[i]) & (
            frames.taxel_indices == contacts.taxel_indices[i]
        )
        np.testing.assert_allclose(contacts.positions[i], frames.positions[match][0], atol=1e-12)
    # Normals point from each pad toward the cylinder axis.
    to_axis = np.array([0.4, 0.0]) - contacts.positions[:, :2]
    assert np.all(np.einsum("ij,ij->i", contacts.normals[:, :2], to_axis) > 0)
    np.testing.assert_allclose(np.abs(contacts.normals[:, 0]), 1.0, atol=1e-9)


def _grasped_box(client: int) -> tuple[Hand, int, float]:
    pb.setGravity(0, 0, -9.81, physicsClientId=client)
    plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
    pb.createMultiBody(0, plane, physicsClientId=client)
    shape = pb.createCollisionShape(
        pb.GEOM_BOX, halfExtents=[0.021, 0.04, 0.06], physicsClientId=client
    )
    box = pb.createMultiBody(0.2, shape, basePosition=[0.5, 0.1, 0.06], physicsClientId=client)
    pb.changeDynamics(box, -1, lateralFriction=0.5, physicsClientId=client)
    hand = Hand.load(client, "pg70")
    # Row i of a pad sits at palm - 125 mm - (i - 6.5) * 3.4 mm; with the palm at 241.6 mm
    # the box top (120 mm) lies midway between rows 5 and 6.
    palm_z = 0.2416
    plan = GraspPlan("pg70", "ok", _top_down(0.5, 0.1, palm_z), 0.05, 0.065, np.array([1.0, 0, 0]))
    outcome = execute_grasp(client, hand, plan, box)
    assert outcome.executed, outcome.reason
    return hand, box, palm_z


def test_grasped_box_contacts_lie_on_its_two_faces(client):
    hand, box, _ = _grasped_box(client)
    contacts = PybulletTaxels().read(_world(client, hand, box), None)
    # Rows 6..13 (8 rows) lie below the top, all 6 columns inside the 80 mm deep box.
    assert len(contacts) == 2 * 8 * 6
    for pad in ("left", "right"):
        rows = contacts.taxel_indices[contacts.pads == pad] // 6
        np.testing.assert_array_equal(np.unique(rows), np.arange(6, 14))
    position, orientation = pb.getBasePositionAndOrientation(box, physicsClientId=client)
    rotation = np.array(pb.getMatrixFromQuaternion(orientation)).reshape(3, 3)
    in_box = (contacts.positions - position) @ rotation
    np.testing.assert_allclose(np.abs(in_box[:, 0]), 0.021, atol=0.5 * MM)
    assert np.all(np.abs(in_box[:, 1]) < 0.04) and np.all(in_box[:, 2] < 0.06)
    # Normals point into the box.
    assert np.all(np.einsum("ij,ij->i", contacts.normals, position - contacts.positions) > 0)


def test_noise_and_dead_taxels_draw_from_the_world_rng(client):
    hand, box, _ = _grasped_box(client)
    clean = PybulletTaxels().read(_world(client, hand, box), None)
    std = 0.001
    noisy_model = PybulletTaxels(PybulletTaxels.Params(position_noise_std_m=std))
    noisy = noisy_model.read(_world(client, hand, box, seed=7), None)
    again = noisy_model.read(_world(client, hand, box, seed=7), None)
    np.testing.assert_array_equal(noisy.positions, again.positions)
    errors = (noisy.positions - clean.positions).ravel()
    # 288 samples: the sample std is within 15 % of sigma with overwhelming probability.
    assert np.std(errors) == pytest.approx(std, rel=0.15)
    np.testing.assert_array_equal(noisy.normals, clean.normals)

    half = PybulletTaxels(PybulletTaxels.Params(dead_taxel_probability=0.5))
    kept = len(half.read(_world(client, hand, box, seed=3), None))
    # Binomial(96, 0.5): 5 sigma is about 24.
    assert abs(kept - len(clean) / 2) < 24
    dead = PybulletTaxels(PybulletTaxels.Params(dead_taxel_probability=1.0))
    nothing = dead.read(_world(client, hand, box), None)
    assert len(nothing) == 0 and nothing.positions.shape == (0, 3)


def test_an_open_hand_far_from_the_object_reports_nothing(client):
    hand, box, palm_z = _grasped_box(client)
    hand.reset_pose(_top_down(0.5, 0.1, palm_z + 0.3))
    assert len(PybulletTaxels().read(_world(client, hand, box), None)) == 0


def test_curved_distal_rows_lift_off_a_flat_face_as_the_59_mm_arc_predicts(client):
    """SDH-2 distal pad 0.2 mm from a large flat face parallel to its flat rows: row i
    (unrolled arc length s past the start of the curve, angle s / R) sees the face at
    (0.2 mm + R (1 - cos(s / R))) / cos(s / R) along its normal."""
    radius, clearance, threshold = 0.059, 0.0002, 0.001
    hand = Hand.load(client, "sdh")
    hand.reset_pose(_top_down(0.0, 0.0, 0.5))
    hand.set_opening(0.1, np.deg2rad(60.0))
    rotations, origins = hand.pad_poses()
    pad = hand.pad_ids.index("thumb_distal")
    normal = rotations[pad][:, 2]
    half = np.array([0.05, 0.05, 0.01])  # pad frame: x along rows, y across, z normal
    centre = origins[pad] + (clearance + half[2]) * normal
    quaternion = Rotation.from_matrix(rotations[pad]).as_quat()
    shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=client)
    face = pb.createMultiBody(
        0, shape, basePosition=centre, baseOrientation=quaternion, physicsClientId=client
    )
    model = PybulletTaxels(PybulletTaxels.Params(contact_threshold_m=threshold))
    contacts = model.read(_world(client, hand, face), None)

    rows = np.arange(13)
    arc = np.clip((rows - 3.5) * PITCH, 0.0, None)  # rows 0-3 flat, 4-12 on the curve
    angle = arc / radius
    gap = (clearance + radius * (1.0 - np.cos(angle))) / np.cos(angle)
    expected_rows = rows[gap <= threshold]
    np.testing.assert_array_equal(expected_rows, np.arange(7))  # the oracle is not trivial
    got = contacts.taxel_indices[contacts.pads == "thumb_distal"]
    np.testing.assert_array_equal(np.sort(got), np.arange(len(expected_rows) * 6))
