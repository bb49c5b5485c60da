"""The shipped hands as data, and what every simulated hand does with them, whatever the
physics engine: opening configurations, closure limits, taxel frames.

Two hands ship with symfuse, described by ``robots/pg70.urdf`` and ``robots/sdh2.urdf``
(numbers from the datasheets; the URDF headers explain each one):

* ``"pg70"`` - Schunk PG-70 parallel gripper, pads ``"left"`` and ``"right"`` (6 x 14).
* ``"sdh"`` - Schunk SDH-2 three-finger hand, pads ``"<finger>_<link>"`` for fingers
  ``f1``, ``f2``, ``thumb`` and links ``proximal`` (6 x 14) and ``distal`` (6 x 13, the
  9 rows nearest the tip curved).

Hand frame (the URDF base link ``palm``): origin at the mounting flange on the palm axis,
``z`` along the approach direction toward the fingertips, ``x`` the closing direction. A
:class:`pipeline.types.GraspPlan`'s ``T_robot_hand`` is this frame's pose. Where the pads
and fingertips sit is read from the URDFs (:mod:`pipeline.io.hand_urdf`; docs/hands.md);
``GripperSpec.finger_length_m`` holds the fingertip depth.

Opening: for a parallel gripper ``opening_m`` is the distance between the pad surfaces,
split evenly between the jaws (:func:`parallel_hand_model`, the PG-70's and a user's
gripper's). For the SDH-2 it is twice the distance from the palm axis of the distal pads'
flat surfaces when each proximal link is tilted by ``alpha`` and the distal link held
parallel to the palm axis (distal joint ``-alpha``;
:class:`pipeline.planning.sdh_geometry.FingerKinematics`); at spread 60 deg that is the
diameter of the circle the three distal pads touch. The narrowest openings flex the
proximal links inward (``alpha > 0``), for narrow objects.

:class:`SimHand` is the engine-neutral part of a simulated hand; the PyBullet hand
(:class:`pipeline.sim.hands.Hand`) and the MuJoCo hand (:mod:`pipeline.sim.mujoco`)
derive from it and add the engine's calls. No simulator is imported here.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import ConfigError
from pipeline.geometry.pad_layout import pad_grid
from pipeline.io.hand_urdf import (
    PadGeometry,
    gripper_spec_from_urdf,
    hand_geometry,
    hand_urdf_path,
)
from pipeline.planning import sdh_geometry
from pipeline.sim.taxels import taxels_to_robot
from pipeline.types import GraspPlan, GripperSpec, PadLayout, TaxelState

#: Where an unused hand waits: high above the table, out of the camera's view (m).
PARK_POSITION_M = (0.0, 0.0, 2.0)

#: The taxels' pitch on every pad of the simulated hands (m): the Weiss DSA 9205's.
TAXEL_PITCH_M = 0.0034
#: How far (m) a parallel gripper's jaw targets move past the touch to press.
JAW_SQUEEZE_M = 0.002

#: The SDH-2's finger kinematics, read from ``robots/sdh2.urdf``.
SDH = sdh_geometry.shipped()
SDH_FINGERS = SDH.fingers
#: How far (rad, each bending joint) an SDH-2 finger's targets move past the contact to press.
#: Fingers 1 and 2 together overpower the thumb and push the object toward it until they
#: reach their targets, so theirs is small (about 4 mm at the distal pad); the thumb's is
#: large so that it presses with its full force cap.
SDH_FINGER_SQUEEZE_RAD = 0.03
SDH_THUMB_SQUEEZE_RAD = 0.1


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
    aperture: Callable[[SimHand], float]
    #: ``(F, 2)`` unit directions each finger closes along in the palm's xy plane, for a
    #: spread (:attr:`fingers` order).
    facings: Callable[[float], np.ndarray]


def _sdh_open_configuration(opening_m: float, spread_rad: float) -> dict[str, float]:
    alpha = SDH.alpha_for_opening(opening_m)
    configuration = {"f1_base": spread_rad, "f2_base": spread_rad}
    for finger in SDH_FINGERS:
        configuration[f"{finger}_proximal"] = alpha
        configuration[f"{finger}_distal"] = -alpha
    return configuration


def _sdh_aperture(hand: SimHand) -> float:
    """Twice the mean distance of the distal pad frames from the palm axis."""
    T_robot_hand = hand.pose()
    origins_robot = hand.pad_poses()[1]
    radii = []
    for finger in SDH_FINGERS:
        offset_robot = origins_robot[hand.pad_ids.index(f"{finger}_distal")] - T_robot_hand[:3, 3]
        offset_hand = T_robot_hand[:3, :3].T @ offset_robot
        radii.append(math.hypot(offset_hand[0], offset_hand[1]))
    return 2.0 * float(np.mean(radii))


def parallel_hand_model(name: str, urdf: str | Path) -> HandModel:
    """The model of a parallel gripper from its URDF (a path, or a file of ``robots/``;
    the convention of docs/hands.md): each jaw a finger closing its prismatic joint at the
    joints' velocity limit and pressing :data:`JAW_SQUEEZE_M` past the touch, each pad a
    grid of as many :data:`TAXEL_PITCH_M` taxels as fit it, the opening split evenly
    between the jaws.

    Raises:
        ConfigError: the URDF is not a parallel gripper of the convention.
    """
    geometry = hand_geometry(str(urdf))
    if not geometry.jaws or len(geometry.closing) != len(geometry.jaws):
        raise ConfigError(
            f"hand '{name}': {geometry.urdf} is not a parallel gripper (jaws on prismatic "
            f"joints, each with a pad; docs/hands.md)"
        )
    mounts = [geometry.pad(closing.pad) for closing in geometry.closing]
    pads = tuple(
        PadGeometry(
            PadLayout(
                mount.pad,
                mount.link,
                int(mount.length_m / TAXEL_PITCH_M + 1e-9),
                int(mount.width_m / TAXEL_PITCH_M + 1e-9),
                TAXEL_PITCH_M,
            )
        )
        for mount in mounts
    )
    fingers = tuple(
        FingerDrive(
            mount.finger, (mount.pad,), (joint,), (-1.0,), geometry.jaw_speed_m_s, (-JAW_SQUEEZE_M,)
        )
        for mount, joint in zip(mounts, geometry.jaws, strict=True)
    )
    closed_m = geometry.jaw_closed_m  # the part of the opening no joint makes
    facings = np.array([closing.facing for closing in geometry.closing])

    def open_configuration(opening_m: float, spread_rad: float) -> dict[str, float]:
        share_m = (opening_m - closed_m) / len(geometry.jaws)
        return {joint: share_m for joint in geometry.jaws}

    def aperture(hand: SimHand) -> float:
        joints = hand.joint_positions()
        return sum(joints[joint] for joint in geometry.jaws) + closed_m

    return HandModel(
        gripper_spec_from_urdf(name, urdf, pads),
        str(hand_urdf_path(urdf)),
        pads,
        fingers,
        open_configuration,
        aperture,
        lambda spread_rad: facings,
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
    max_aperture_m = SDH.opening_for_alpha(-SDH.joint_limit_rad)
    spec = gripper_spec_from_urdf("sdh", "sdh2.urdf", pads, max_aperture_m)
    return HandModel(
        spec,
        "sdh2.urdf",
        tuple(pads),
        tuple(fingers),
        _sdh_open_configuration,
        _sdh_aperture,
        SDH.finger_facings,
    )


HAND_MODELS: dict[str, HandModel] = {
    "pg70": parallel_hand_model("pg70", "pg70.urdf"),
    "sdh": _sdh_model(),
}

#: What grasp planners need to know about each shipped hand, by name.
GRIPPERS: dict[str, GripperSpec] = {name: model.spec for name, model in HAND_MODELS.items()}


#: Hands a world added in this process by their URDFs (:func:`add_parallel_hand`), by name.
ADDED_HANDS: dict[str, HandModel] = {}


def hand_model(name: str) -> HandModel:
    """The model of the shipped or added hand ``name``.

    Raises:
        ConfigError: no hand has that name.
    """
    model = HAND_MODELS.get(name) or ADDED_HANDS.get(name)
    if model is None:
        known = ", ".join(sorted({*HAND_MODELS, *ADDED_HANDS}))
        raise ConfigError(f"unknown gripper '{name}' (known: {known})")
    return model


def add_parallel_hand(name: str, urdf: str | Path) -> GripperSpec:
    """Make the parallel gripper of ``urdf`` (:func:`parallel_hand_model`) a hand the
    simulated worlds can load under ``name`` (in this process, :data:`ADDED_HANDS`), and
    give its spec; again with the same URDF, nothing changes.

    Raises:
        ConfigError: ``name`` is a shipped hand or an added one with another URDF, or the
            URDF is no parallel gripper.
    """
    path = str(hand_urdf_path(urdf))
    if name in HAND_MODELS:
        raise ConfigError(f"hand '{name}' is a shipped hand; name {path} otherwise")
    known = ADDED_HANDS.get(name)
    if known is not None:
        if known.urdf != path:
            raise ConfigError(f"hand '{name}' is {known.urdf} already, not {path}")
        return known.spec
    model = parallel_hand_model(name, path)
    ADDED_HANDS[name] = model
    return model.spec


class SimHand(ABC):
    """A shipped hand in a simulator: what the grasp sequence
    (:mod:`pipeline.sim.grasp_sequence`) and tactile reads need, in frame R.

    Subclasses read the joint limits and effort caps from the loaded URDF, call
    :meth:`_setup` with them, and implement the engine's part (pose, joints, pads,
    contacts). ``object_id`` arguments name the grasped body in the engine's own ids.

    Attributes:
        model: the hand's :class:`HandModel`.
        spec: its :class:`GripperSpec`.
        pad_ids: pad ids, in the order of :attr:`HandModel.pads`.
    """

    def _setup(
        self,
        model: HandModel,
        joint_limits: dict[str, tuple[float, float]],
        joint_effort: dict[str, float],
    ) -> None:
        self.model = model
        self.spec = model.spec
        self.pad_ids = [pad.layout.name for pad in model.pads]
        self._joint_limits = joint_limits
        self._joint_effort = joint_effort
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

    # ------------------------------------------------------------------ engine part
    @abstractmethod
    def pose(self) -> np.ndarray:
        """``T_robot_hand``: the palm frame's current pose in frame R."""

    @abstractmethod
    def reset_pose(self, T_robot_hand: np.ndarray) -> None:
        """Teleport the palm to ``T_robot_hand`` (no dynamics) and hold it there."""

    @abstractmethod
    def move_to(self, T_robot_hand: np.ndarray) -> None:
        """Set the palm's target pose; the dynamics pull the hand there."""

    @abstractmethod
    def joint_positions(self) -> dict[str, float]:
        """Current position of every movable joint (rad or m), by joint name."""

    @abstractmethod
    def _reset_joints(self, configuration: dict[str, float]) -> None:
        """Teleport the joints to ``configuration`` at rest (no dynamics)."""

    @abstractmethod
    def command(self, targets: dict[str, float], force_fraction: float = 1.0) -> None:
        """Position-control joints toward ``targets`` (clipped to their limits), each with
        ``force_fraction`` of its URDF effort limit as the force/torque cap."""

    @abstractmethod
    def pad_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """``(rotations (P, 3, 3), origins (P, 3))`` of the pad frames in frame R."""

    @abstractmethod
    def taxel_gaps(
        self, object_id: int, behind_m: float, beyond_m: float
    ) -> tuple[TaxelFrames, np.ndarray]:
        """The taxel frames and ``(N,)`` signed gaps (m) from each taxel's surface to the
        object along its normal, probed from ``behind_m`` inside the pad to ``beyond_m``
        past it, the hand itself ignored (negative = pressed in; ``+inf`` where the probe
        meets nothing, or something other than the object first)."""

    @abstractmethod
    def pad_contact_forces(self, object_id: int) -> np.ndarray:
        """``(P,)`` summed contact normal force (N) between each pad and the object."""

    @abstractmethod
    def finger_contact_forces(self, object_id: int) -> np.ndarray:
        """``(F,)`` summed contact normal force (N) between each finger (all its links, pads
        included; :attr:`HandModel.fingers` order) and the object."""

    @abstractmethod
    def bearing_down(self, object_id: int) -> tuple[int | None, float]:
        """How hard the hand bears down on the object now: the summed upward component of
        the hand-object contact normal forces (N; what a wrist force sensor reads as the
        descent meeting resistance, not a finger brushing a side) and the finger bearing
        hardest (:attr:`HandModel.fingers` index; None for the palm or no contact)."""

    @abstractmethod
    def touches(self, object_id: int) -> bool:
        """True when any part of the hand is in contact with the object now."""

    # ------------------------------------------------------------------ shared part
    def park(self, park_position_m: tuple[float, float, float] = PARK_POSITION_M) -> None:
        """Teleport the hand, fully open and pointing down, to ``park_position_m``."""
        T_park = np.eye(4)
        T_park[:3, :3] = np.diag([1.0, -1.0, -1.0])
        T_park[:3, 3] = park_position_m
        self.reset_pose(T_park)
        self.set_opening(self.spec.max_aperture_m, 0.0)

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
        self._reset_joints(configuration)
        self.command(configuration)

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


def hand_link_meshes(
    gripper: str,
    joint_positions: dict[str, float] | None,
    T_robot_hand: np.ndarray,
    plan: GraspPlan,
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``link -> (vertices, faces, vertex normals)`` of the shipped hand ``gripper`` in
    frame R, from its URDF's forward kinematics with the palm at ``T_robot_hand`` and the
    joints at ``joint_positions`` (or opened as ``plan`` says); empty for another hand.
    Each face gets its own vertices, so the boxes and cylinders of the URDF shade flat
    (what :meth:`pipeline.stages.World.hand_meshes` gives of a simulated world's hands)."""
    import trimesh
    import yourdfpy

    from robots import ROOT

    model = HAND_MODELS.get(gripper) or ADDED_HANDS.get(gripper)
    if model is None:
        return {}
    urdf = yourdfpy.URDF.load(str(ROOT / model.urdf))
    if joint_positions is None:
        joint_positions = model.open_configuration(plan.opening_m, plan.spread_rad)
    urdf.update_cfg({k: v for k, v in joint_positions.items() if k in urdf.actuated_joint_names})
    scene = urdf.scene
    shapes: dict[str, list[trimesh.Trimesh]] = {}
    for node in scene.graph.nodes_geometry:
        T_hand_shape, geometry = scene.graph[node]
        link = scene.graph.transforms.parents[node]
        shape = trimesh.Trimesh(scene.geometry[geometry].vertices, scene.geometry[geometry].faces)
        shapes.setdefault(link, []).append(shape.apply_transform(T_robot_hand @ T_hand_shape))
    meshes = {}
    for link, parts in shapes.items():
        mesh = trimesh.util.concatenate(parts)
        mesh.unmerge_vertices()
        meshes[link] = (np.asarray(mesh.vertices), np.asarray(mesh.faces), mesh.vertex_normals)
    return meshes
