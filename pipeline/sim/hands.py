"""The PyBullet hand: a shipped hand (:mod:`pipeline.sim.hand_models`) loaded from its URDF
into a PyBullet client, opened, moved and closed.

The hand's base floats freely in PyBullet and is held by a fixed constraint whose target
:meth:`Hand.move_to` sets (PyBullet's world frame is the robot frame ``R``).
"""

from __future__ import annotations

import numpy as np
import pybullet as pb
from scipy.spatial.transform import Rotation

from pipeline.sim.hand_models import (
    GRIPPERS,
    HAND_MODELS,
    PARK_POSITION_M,
    HandModel,
    SimHand,
    TaxelFrames,
    hand_model,
)
from pipeline.sim.taxels import (
    ray_segments,
    rotations_from_quaternions,
    segments_near_box,
    surface_gaps,
)
from robots import ROOT as ROBOTS_ROOT

__all__ = ["GRIPPERS", "HAND_MODELS", "PARK_POSITION_M", "Hand"]

#: Force of the constraint that holds the hand's base at its target pose (N).
BASE_HOLD_FORCE_N = 2000.0
#: Proportional gain of PyBullet's joint position servo (dimensionless, 0..1).
POSITION_GAIN = 0.3
#: Collision-filter group of every hand link. The hand still collides with everything;
#: taxel probe rays leave this group out of their mask so they never stop on the hand.
HAND_COLLISION_GROUP = 1 << 5


def _transform(position: np.ndarray, quaternion_xyzw: np.ndarray) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3] = rotations_from_quaternions(quaternion_xyzw)[0]
    transform[:3, 3] = position
    return transform


def _quaternion(rotation: np.ndarray) -> tuple[float, ...]:
    return tuple(Rotation.from_matrix(rotation).as_quat())


class Hand(SimHand):
    """A hand loaded into a PyBullet client.

    Attributes:
        client: the PyBullet physics client id.
        body_id: the PyBullet body.
    """

    def __init__(self, client: int, model: HandModel, body_id: int, constraint_id: int) -> None:
        self.client = client
        self.body_id = body_id
        self._constraint_id = constraint_id

        self._joint_index: dict[str, int] = {}
        joint_limits: dict[str, tuple[float, float]] = {}
        joint_effort: dict[str, float] = {}
        link_index: dict[str, int] = {}
        for index in range(pb.getNumJoints(body_id, physicsClientId=client)):
            info = pb.getJointInfo(body_id, index, physicsClientId=client)
            link_index[info[12].decode()] = index
            if info[2] in (pb.JOINT_REVOLUTE, pb.JOINT_PRISMATIC):
                name = info[1].decode()
                self._joint_index[name] = index
                joint_limits[name] = (info[8], info[9])
                joint_effort[name] = info[10]
        self._setup(model, joint_limits, joint_effort)
        self._pad_links = [link_index[pad.layout.link] for pad in model.pads]
        # Each finger's links: those named after it (f1_knuckle, f1_proximal_pad, left_jaw...).
        self._finger_of_link = {
            index: i
            for name, index in link_index.items()
            for i, finger in enumerate(model.fingers)
            if name.startswith(f"{finger.name}_")
        }
        self._links = [-1, *link_index.values()]

        inertial = pb.getDynamicsInfo(body_id, -1, physicsClientId=client)
        self._T_com_palm = np.linalg.inv(_transform(np.array(inertial[3]), np.array(inertial[4])))

    def remove(self) -> None:
        """Take the hand out of its client: its holding constraint and its body."""
        pb.removeConstraint(self._constraint_id, physicsClientId=self.client)
        pb.removeBody(self.body_id, physicsClientId=self.client)

    @classmethod
    def load(
        cls,
        client: int,
        gripper: str,
        park_position_m: tuple[float, float, float] = PARK_POSITION_M,
    ) -> Hand:
        """Load a shipped hand (``"pg70"`` or ``"sdh"``) into an existing PyBullet client.

        The hand is parked at ``park_position_m`` pointing down (z of the hand = -z of R),
        fully open, its base held there by a fixed constraint.

        Raises:
            ConfigError: unknown gripper name.
        """
        model = hand_model(gripper)
        body_id = pb.loadURDF(
            str(ROBOTS_ROOT / model.urdf),
            basePosition=park_position_m,
            useFixedBase=False,
            flags=pb.URDF_USE_INERTIA_FROM_FILE,
            physicsClientId=client,
        )
        inertial = pb.getDynamicsInfo(body_id, -1, physicsClientId=client)
        constraint_id = pb.createConstraint(
            body_id,
            -1,
            -1,
            -1,
            pb.JOINT_FIXED,
            (0.0, 0.0, 0.0),
            parentFramePosition=[-c for c in inertial[3]],
            childFramePosition=park_position_m,
            physicsClientId=client,
        )
        hand = cls(client, model, body_id, constraint_id)
        for link in hand._links:
            pb.setCollisionFilterGroupMask(
                body_id, link, HAND_COLLISION_GROUP, -1, physicsClientId=client
            )
        for link in hand._pad_links:
            pb.changeDynamics(body_id, link, lateralFriction=1.0, physicsClientId=client)
        hand.park(park_position_m)
        return hand

    # ------------------------------------------------------------------ base pose
    def pose(self) -> np.ndarray:
        """``T_robot_hand``: the palm frame's current pose in frame R."""
        position, orientation = pb.getBasePositionAndOrientation(
            self.body_id, physicsClientId=self.client
        )
        return _transform(np.array(position), np.array(orientation)) @ self._T_com_palm

    def reset_pose(self, T_robot_hand: np.ndarray) -> None:
        """Teleport the palm to ``T_robot_hand`` (no dynamics) and hold it there."""
        T_robot_com = np.asarray(T_robot_hand) @ np.linalg.inv(self._T_com_palm)
        pb.resetBasePositionAndOrientation(
            self.body_id,
            T_robot_com[:3, 3],
            _quaternion(T_robot_com[:3, :3]),
            physicsClientId=self.client,
        )
        pb.resetBaseVelocity(self.body_id, (0, 0, 0), (0, 0, 0), physicsClientId=self.client)
        self.move_to(T_robot_hand)

    def move_to(self, T_robot_hand: np.ndarray, max_force_N: float = BASE_HOLD_FORCE_N) -> None:
        """Set the base constraint's target to ``T_robot_hand``; dynamics pull the hand there."""
        T = np.asarray(T_robot_hand)
        pb.changeConstraint(
            self._constraint_id,
            jointChildPivot=T[:3, 3],
            jointChildFrameOrientation=_quaternion(T[:3, :3]),
            maxForce=max_force_N,
            physicsClientId=self.client,
        )

    # ------------------------------------------------------------------ joints
    def joint_positions(self) -> dict[str, float]:
        """Current position of every movable joint (rad or m), by joint name."""
        states = pb.getJointStates(
            self.body_id, list(self._joint_index.values()), physicsClientId=self.client
        )
        return {name: state[0] for name, state in zip(self._joint_index, states, strict=True)}

    def _reset_joints(self, configuration: dict[str, float]) -> None:
        for name, value in configuration.items():
            pb.resetJointState(
                self.body_id, self._joint_index[name], value, 0.0, physicsClientId=self.client
            )

    def command(self, targets: dict[str, float], force_fraction: float = 1.0) -> None:
        """Position-control joints toward ``targets`` (clipped to their limits), each with
        ``force_fraction`` of its URDF effort limit as the force/torque cap."""
        names = list(targets)
        positions = [float(np.clip(targets[n], *self._joint_limits[n])) for n in names]
        pb.setJointMotorControlArray(
            self.body_id,
            [self._joint_index[n] for n in names],
            pb.POSITION_CONTROL,
            targetPositions=positions,
            forces=[force_fraction * self._joint_effort[n] for n in names],
            positionGains=[POSITION_GAIN] * len(names),
            physicsClientId=self.client,
        )

    # ------------------------------------------------------------------ pads and taxels
    def pad_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """``(rotations (P, 3, 3), origins (P, 3))`` of the pad frames in frame R."""
        states = pb.getLinkStates(
            self.body_id,
            self._pad_links,
            computeForwardKinematics=True,
            physicsClientId=self.client,
        )
        origins = np.array([s[4] for s in states])
        rotations = rotations_from_quaternions(np.array([s[5] for s in states]))
        return rotations, origins

    def taxel_gaps(
        self, object_id: int, behind_m: float, beyond_m: float
    ) -> tuple[TaxelFrames, np.ndarray]:
        """Ray-probe the object along every taxel normal (one batched ray test for the rays
        that reach the object's bounding box).

        Each ray runs from ``behind_m`` inside the pad to ``beyond_m`` past its surface and
        ignores the hand itself. A ray that starts inside the object reports a hit at its
        start (gap ``-behind_m``) when Bullet detects it, and no hit otherwise.

        Returns:
            The taxel frames and ``(N,)`` signed gaps (metres) from each taxel's surface to
            the object along its normal (negative = pressed in); ``+inf`` where the ray
            hits nothing or something other than ``object_id`` first.
        """
        frames = self.taxel_frames()
        starts, ends = ray_segments(frames.positions, frames.normals, behind_m, beyond_m)
        box_min, box_max = self._object_aabb(object_id)
        candidates = np.flatnonzero(segments_near_box(starts, ends, box_min, box_max))
        fractions = np.ones(len(starts))
        if len(candidates):
            hits = pb.rayTestBatch(
                starts[candidates],
                ends[candidates],
                collisionFilterMask=~HAND_COLLISION_GROUP,
                numThreads=0,  # all cores: the ray tests are independent
                physicsClientId=self.client,
            )
            bodies = np.fromiter((h[0] for h in hits), dtype=np.int64, count=len(hits))
            hit_fractions = np.fromiter((h[2] for h in hits), dtype=np.float64, count=len(hits))
            fractions[candidates] = np.where(bodies == object_id, hit_fractions, 1.0)
        return frames, surface_gaps(fractions, behind_m, beyond_m)

    def _object_aabb(self, object_id: int) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds of all of a body's links in frame R."""
        links = range(-1, pb.getNumJoints(object_id, physicsClientId=self.client))
        boxes = np.array(
            [pb.getAABB(object_id, link, physicsClientId=self.client) for link in links]
        )
        return boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)

    def pad_contact_forces(self, object_id: int) -> np.ndarray:
        """``(P,)`` summed contact normal force (N) between each pad and the object."""
        forces = np.zeros(len(self._pad_links))
        row_of_link = {link: i for i, link in enumerate(self._pad_links)}
        for contact in pb.getContactPoints(
            bodyA=self.body_id, bodyB=object_id, physicsClientId=self.client
        ):
            row = row_of_link.get(contact[3])
            if row is not None:
                forces[row] += contact[9]
        return forces

    def finger_contact_forces(self, object_id: int) -> np.ndarray:
        """``(F,)`` summed contact normal force (N) between each finger (all its links, pads
        included; :attr:`HandModel.fingers` order) and the object."""
        forces = np.zeros(len(self.model.fingers))
        for contact in pb.getContactPoints(
            bodyA=self.body_id, bodyB=object_id, physicsClientId=self.client
        ):
            finger = self._finger_of_link.get(contact[3])
            if finger is not None:
                forces[finger] += contact[9]
        return forces

    def bearing_down(self, object_id: int) -> tuple[int | None, float]:
        """How hard the hand bears down on the object now: the summed upward component of
        the hand-object contact normal forces (N; what a wrist force sensor reads as the
        descent meeting resistance, not a finger brushing a side) and the finger bearing
        hardest (:attr:`HandModel.fingers` index; None for the palm or no contact)."""
        upward = [
            (contact[9] * max(contact[7][2], 0.0), contact[3])
            for contact in pb.getContactPoints(
                bodyA=self.body_id, bodyB=object_id, physicsClientId=self.client
            )
        ]
        if not upward:
            return None, 0.0
        link = max(upward)[1]
        return self._finger_of_link.get(link), float(sum(force for force, _ in upward))

    def touches(self, object_id: int) -> bool:
        """True when any part of the hand is in contact with the object now."""
        return bool(
            pb.getContactPoints(bodyA=self.body_id, bodyB=object_id, physicsClientId=self.client)
        )
