"""The simulated hands: gripper specs, and a PyBullet hand that opens, moves and closes.

Two hands ship with symfuse, described by ``robots/pg70.urdf`` and ``robots/sdh2.urdf``
(numbers from the datasheets; the URDF headers explain each one):

* ``"pg70"`` - Schunk PG-70 parallel gripper, pads ``"left"`` and ``"right"`` (6 x 14).
* ``"sdh"`` - Schunk SDH-2 three-finger hand, pads ``"<finger>_<link>"`` for fingers
  ``f1``, ``f2``, ``thumb`` and links ``proximal`` (6 x 14) and ``distal`` (6 x 13, the
  9 rows nearest the tip curved).

Hand frame (the URDF base link ``palm``): origin at the mounting flange on the palm axis,
``z`` along the approach direction toward the fingertips, ``x`` the closing direction. A
:class:`pipeline.types.GraspPlan`'s ``T_robot_hand`` is this frame's pose. The PG-70's pad
centres are 125 mm and its fingertips 154 mm down ``z``; the SDH-2's straight fingertips
246 mm (``GripperSpec.finger_length_m`` holds the fingertip depth).

Opening: for the PG-70 ``opening_m`` is the distance between the pad surfaces. For the
SDH-2 it is twice the distance from the palm axis of the distal pads' flat surfaces when
each proximal link is tilted by ``alpha`` and the distal link held parallel to the palm
axis (distal joint ``-alpha``): ``opening = 2 (r_base - 14.8 mm - 86.5 mm sin(alpha))``
with ``r_base = 38.1 mm`` (:mod:`pipeline.perception.sdh_geometry`); at spread 60 deg that
is the diameter of the circle the three distal pads touch. Openings below 46.6 mm flex the
proximal links inward (``alpha > 0``), for narrow objects.

The hand's base floats freely in PyBullet and is held by a fixed constraint whose target
:meth:`Hand.move_to` sets (PyBullet's world frame is the robot frame ``R``).

One module because the two hands' models (:class:`HandModel`: pads, finger drives, opening
and aperture functions of a :class:`Hand`) are the data the :class:`Hand` drives, and the
:class:`Hand` itself, one PyBullet body opened, moved and closed, is most of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as pb
from scipy.spatial.transform import Rotation

from robots import ROOT as ROBOTS_ROOT

from ..errors import ConfigError
from ..pad_layout import pad_grid
from ..perception import sdh_geometry
from ..types import GripperSpec, PadLayout, TaxelState
from .taxels import (
    ray_segments,
    rotations_from_quaternions,
    segments_near_box,
    surface_gaps,
    taxels_to_robot,
)

TAXEL_PITCH_M = 0.0034

SDH_FINGERS = sdh_geometry.FINGERS
#: How far (rad, each bending joint) an SDH-2 finger's targets move past the contact to press.
#: Fingers 1 and 2 together overpower the thumb and push the object toward it until they
#: reach their targets, so theirs is small (about 4 mm at the distal pad); the thumb's is
#: large so that it presses with its full force cap.
SDH_FINGER_SQUEEZE_RAD = 0.03
SDH_THUMB_SQUEEZE_RAD = 0.1

#: Where an unused hand waits: high above the table, out of the camera's view (m).
PARK_POSITION_M = (0.0, 0.0, 2.0)
#: Force of the constraint that holds the hand's base at its target pose (N).
BASE_HOLD_FORCE_N = 2000.0
#: Proportional gain of PyBullet's joint position servo (dimensionless, 0..1).
POSITION_GAIN = 0.3
#: Collision-filter group of every hand link. The hand still collides with everything;
#: taxel probe rays leave this group out of their mask so they never stop on the hand.
HAND_COLLISION_GROUP = 1 << 5


@dataclass(frozen=True)
class PadGeometry:
    """A pad's layout plus the shape of its surface (see :func:`pipeline.pad_layout.pad_grid`)."""

    layout: PadLayout
    curved_rows: int = 0
    curve_radius_m: float = math.inf


@dataclass(frozen=True)
class FingerDrive:
    """How one finger closes: each joint's target is its open value + ``ratio * closure``.

    ``closure`` grows from 0 (the open configuration) as the finger closes, at ``speed``
    closure units per second (metres for a prismatic jaw, radians for a bending finger).
    Once the finger touches, each joint's target moves ``squeeze`` (m or rad) further
    toward the object, so that the blocked motors press with their force caps.
    """

    name: str
    pads: tuple[str, ...]
    joints: tuple[str, ...]
    ratios: tuple[float, ...]
    speed: float
    squeeze: tuple[float, ...]


@dataclass(frozen=True)
class TaxelFrames:
    """Every taxel of a hand in frame R, from forward kinematics of its current state.

    Attributes:
        positions: ``(N, 3)`` taxel centres on the pad surfaces, metres.
        normals: ``(N, 3)`` unit normals pointing out of the pads.
        pads: ``(N,)`` pad id of each taxel (str).
        taxel_indices: ``(N,)`` row-major index of each taxel within its pad.
    """

    positions: np.ndarray
    normals: np.ndarray
    pads: np.ndarray
    taxel_indices: np.ndarray


@dataclass(frozen=True)
class HandModel:
    """Everything symfuse knows about one hand type."""

    spec: GripperSpec
    urdf: str
    pads: tuple[PadGeometry, ...]
    fingers: tuple[FingerDrive, ...]
    open_configuration: Callable[[float, float], dict[str, float]]
    aperture: Callable[[Hand], float]
    #: ``(F, 2)`` unit directions each finger closes along in the palm's xy plane, for a
    #: spread (:attr:`fingers` order).
    facings: Callable[[float], np.ndarray]


def _pg70_open_configuration(opening_m: float, spread_rad: float) -> dict[str, float]:
    half_m = opening_m / 2.0
    return {"left_jaw": half_m, "right_jaw": half_m}


def _pg70_aperture(hand: Hand) -> float:
    joints = hand.joint_positions()
    return joints["left_jaw"] + joints["right_jaw"]


def _sdh_open_configuration(opening_m: float, spread_rad: float) -> dict[str, float]:
    alpha = sdh_geometry.alpha_for_opening(opening_m)
    configuration = {"f1_base": spread_rad, "f2_base": spread_rad}
    for finger in SDH_FINGERS:
        configuration[f"{finger}_proximal"] = alpha
        configuration[f"{finger}_distal"] = -alpha
    return configuration


def _sdh_aperture(hand: Hand) -> float:
    """Twice the mean distance of the distal pad frames from the palm axis."""
    T_robot_hand = hand.pose()
    origins_robot = hand.pad_poses()[1]
    radii = []
    for finger in SDH_FINGERS:
        offset_robot = origins_robot[hand.pad_ids.index(f"{finger}_distal")] - T_robot_hand[:3, 3]
        offset_hand = T_robot_hand[:3, :3].T @ offset_robot
        radii.append(math.hypot(offset_hand[0], offset_hand[1]))
    return 2.0 * float(np.mean(radii))


def _pg70_model() -> HandModel:
    pads = tuple(
        PadGeometry(PadLayout(side, f"{side}_pad", 14, 6, TAXEL_PITCH_M))
        for side in ("left", "right")
    )
    fingers = tuple(
        FingerDrive(side, (side,), (f"{side}_jaw",), (-1.0,), 0.041, (-0.002,))
        for side in ("left", "right")
    )
    spec = GripperSpec("pg70", 2, 0.065, tuple(p.layout for p in pads), 0.154)
    return HandModel(
        spec,
        "pg70.urdf",
        pads,
        fingers,
        _pg70_open_configuration,
        _pg70_aperture,
        lambda spread_rad: np.array([[1.0, 0.0], [-1.0, 0.0]]),  # left jaw at -x, right at +x
    )


def _sdh_model() -> HandModel:
    pads: list[PadGeometry] = []
    fingers: list[FingerDrive] = []
    for finger in SDH_FINGERS:
        proximal = f"{finger}_proximal"
        distal = f"{finger}_distal"
        pads.append(PadGeometry(PadLayout(proximal, f"{proximal}_pad", 14, 6, TAXEL_PITCH_M)))
        pads.append(
            PadGeometry(
                PadLayout(distal, f"{distal}_pad", 13, 6, TAXEL_PITCH_M),
                sdh_geometry.DISTAL_PAD_CURVED_ROWS,
                sdh_geometry.DISTAL_PAD_CURVE_RADIUS_M,
            )
        )
        squeeze = SDH_THUMB_SQUEEZE_RAD if finger == "thumb" else SDH_FINGER_SQUEEZE_RAD
        fingers.append(
            FingerDrive(
                finger, (proximal, distal), (proximal, distal), (1.0, -1.0), 1.0, (squeeze,) * 2
            )
        )
    max_aperture_m = sdh_geometry.opening_for_alpha(-sdh_geometry.JOINT_LIMIT_RAD)
    spec = GripperSpec("sdh", 3, max_aperture_m, tuple(p.layout for p in pads), 0.246)
    return HandModel(
        spec,
        "sdh2.urdf",
        tuple(pads),
        tuple(fingers),
        _sdh_open_configuration,
        _sdh_aperture,
        sdh_geometry.finger_facings,
    )


HAND_MODELS: dict[str, HandModel] = {"pg70": _pg70_model(), "sdh": _sdh_model()}

#: What grasp planners need to know about each shipped hand, by name.
GRIPPERS: dict[str, GripperSpec] = {name: model.spec for name, model in HAND_MODELS.items()}


def _transform(position: np.ndarray, quaternion_xyzw: np.ndarray) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3] = rotations_from_quaternions(quaternion_xyzw)[0]
    transform[:3, 3] = position
    return transform


def _quaternion(rotation: np.ndarray) -> tuple[float, ...]:
    return tuple(Rotation.from_matrix(rotation).as_quat())


class Hand:
    """A hand loaded into a PyBullet client.

    Attributes:
        client: the PyBullet physics client id.
        model: the hand's :class:`HandModel`.
        spec: its :class:`GripperSpec`.
        body_id: the PyBullet body.
        pad_ids: pad ids, in the order of :attr:`HandModel.pads`.
    """

    def __init__(self, client: int, model: HandModel, body_id: int, constraint_id: int) -> None:
        self.client = client
        self.model = model
        self.spec = model.spec
        self.body_id = body_id
        self._constraint_id = constraint_id
        self.pad_ids = [pad.layout.name for pad in model.pads]

        self._joint_index: dict[str, int] = {}
        self._joint_limits: dict[str, tuple[float, float]] = {}
        self._joint_effort: dict[str, float] = {}
        link_index: dict[str, int] = {}
        for index in range(pb.getNumJoints(body_id, physicsClientId=client)):
            info = pb.getJointInfo(body_id, index, physicsClientId=client)
            link_index[info[12].decode()] = index
            if info[2] in (pb.JOINT_REVOLUTE, pb.JOINT_PRISMATIC):
                name = info[1].decode()
                self._joint_index[name] = index
                self._joint_limits[name] = (info[8], info[9])
                self._joint_effort[name] = info[10]
        self._pad_links = [link_index[pad.layout.link] for pad in model.pads]
        # Each finger's links: those named after it (f1_knuckle, f1_proximal_pad, left_jaw...).
        self._finger_of_link = {
            index: i
            for name, index in link_index.items()
            for i, finger in enumerate(model.fingers)
            if name.startswith(f"{finger.name}_")
        }
        self._links = [-1, *link_index.values()]

        grids = [
            pad_grid(
                p.layout.rows, p.layout.cols, p.layout.pitch_m, p.curved_rows, p.curve_radius_m
            )
            for p in model.pads
        ]
        self._taxel_positions_pad = np.concatenate([g[0] for g in grids])
        self._taxel_normals_pad = np.concatenate([g[1] for g in grids])
        self._pad_of_taxel = np.concatenate(
            [np.full(len(g[0]), i, dtype=np.int64) for i, g in enumerate(grids)]
        )
        self._taxel_pads = np.asarray(self.pad_ids)[self._pad_of_taxel]
        self._taxel_indices = np.concatenate([np.arange(len(g[0])) for g in grids])

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
        if gripper not in HAND_MODELS:
            known = ", ".join(sorted(HAND_MODELS))
            raise ConfigError(f"unknown gripper '{gripper}' (known: {known})")
        model = HAND_MODELS[gripper]
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

    def park(self, park_position_m: tuple[float, float, float] = PARK_POSITION_M) -> None:
        """Teleport the hand, fully open and pointing down, to ``park_position_m``."""
        T_park = np.eye(4)
        T_park[:3, :3] = np.diag([1.0, -1.0, -1.0])
        T_park[:3, 3] = park_position_m
        self.reset_pose(T_park)
        self.set_opening(self.spec.max_aperture_m, 0.0)

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

    def open_configuration(self, opening_m: float, spread_rad: float = 0.0) -> dict[str, float]:
        """Joint positions for an opening (see the module docstring) and an SDH spread.

        Raises:
            ValueError: the opening or spread is outside what the hand can do.
        """
        if not 0.0 <= opening_m <= self.spec.max_aperture_m + 1e-9:
            raise ValueError(
                f"opening {opening_m * 1e3:.1f} mm outside 0..{self.spec.max_aperture_m * 1e3:.1f}"
                f" mm of the {self.spec.name}"
            )
        configuration = self.model.open_configuration(
            min(opening_m, self.spec.max_aperture_m), spread_rad
        )
        for name, value in configuration.items():
            lower, upper = self._joint_limits[name]
            if not lower - 1e-6 <= value <= upper + 1e-6:
                raise ValueError(f"joint {name} = {value:.4f} outside [{lower:.4f}, {upper:.4f}]")
            configuration[name] = min(max(value, lower), upper)
        return configuration

    def set_opening(self, opening_m: float, spread_rad: float = 0.0) -> None:
        """Teleport the fingers to an opening (no dynamics) and hold them there."""
        configuration = self.open_configuration(opening_m, spread_rad)
        for name, value in configuration.items():
            pb.resetJointState(
                self.body_id, self._joint_index[name], value, 0.0, physicsClientId=self.client
            )
        self.command(configuration)

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

    def closure_limit(self, finger: FingerDrive, open_targets: dict[str, float]) -> float:
        """Largest closure before one of the finger's joints reaches its limit."""
        room = []
        for joint, ratio in zip(finger.joints, finger.ratios, strict=True):
            lower, upper = self._joint_limits[joint]
            bound = upper if ratio > 0 else lower
            room.append((bound - open_targets[joint]) / ratio)
        return max(0.0, min(room))

    def aperture(self) -> float:
        """The current opening, measured the way ``opening_m`` is defined (module doc)."""
        return self.model.aperture(self)

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

    def taxel_frames(self) -> TaxelFrames:
        """Every taxel's centre and outward normal in frame R, for the current state."""
        rotations, origins = self.pad_poses()
        positions, normals = taxels_to_robot(
            self._taxel_positions_pad,
            self._taxel_normals_pad,
            self._pad_of_taxel,
            rotations,
            origins,
        )
        return TaxelFrames(positions, normals, self._taxel_pads, self._taxel_indices)

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

    def taxel_state(self, object_id: int, behind_m: float, beyond_m: float) -> TaxelState:
        """:meth:`taxel_gaps` with each taxel's pad force (:meth:`pad_contact_forces`), as
        the :class:`pipeline.stages.World` contract hands them to tactile models."""
        frames, gaps = self.taxel_gaps(object_id, behind_m, beyond_m)
        pad_row = {pad: i for i, pad in enumerate(self.pad_ids)}
        forces = self.pad_contact_forces(object_id)
        return TaxelState(
            positions=frames.positions,
            normals=frames.normals,
            pads=frames.pads,
            taxel_indices=frames.taxel_indices,
            gaps_m=gaps,
            pad_forces_N=forces[[pad_row[pad] for pad in frames.pads]],
        )

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
