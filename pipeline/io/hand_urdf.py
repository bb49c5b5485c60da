"""A hand's shape read from its URDF: :func:`read_hand_geometry` gives the
:class:`~pipeline.types.HandGeometry` planners and the next-grasp scoring place the hand
with, so that no number of a hand is written twice.

The convention a hand's URDF follows (docs/hands.md):

* The root link is the palm. Its frame is the hand frame: origin on the palm axis at the
  mounting flange, z along the approach toward the fingertips, x the closing direction.
  Its collision shapes are the housing.
* Every chain of links hanging from the palm is a finger, named by its links' prefix
  before the first ``_`` (``left_jaw`` is finger ``left``, ``f1_knuckle`` finger ``f1``).
* A tactile pad is a link named ``<pad>_pad`` fixed to the finger link carrying it, its
  frame at the pad surface's centre, z along the outward normal, x along the rows toward
  the fingertip; its collision shapes are the pad.
* A parallel gripper's fingers are jaws on prismatic joints (its joint at 0 puts the pads
  at the narrowest opening, at its upper limit the widest); a turn-and-bend hand's
  fingers are a base joint about z (or fixed), a knuckle, and two bending joints
  (:class:`~pipeline.types.BendingFinger`).

Units are the URDF's: metres and radians. Only boxes and cylinders are read as collision
shapes. A URDF gives its angles to a few decimals (``3.141593`` for pi), whose error would
show in every length measured through a turned frame: derived lengths are rounded to a
micrometre (:data:`LENGTH_DECIMALS`, the finest the shipped URDFs give) and directions
to :data:`DIRECTION_DECIMALS`, so that they are the URDF's numbers summed.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ConfigError
from pipeline.types import (
    BendingFinger,
    ClosingPad,
    GripperSpec,
    HandGeometry,
    Housing,
    PadLayout,
    PadMount,
)

#: Decimal places derived lengths keep (m): a micrometre.
LENGTH_DECIMALS = 6
#: Decimal places derived unit directions keep: a turn given to 1e-6 rad rounds away.
DIRECTION_DECIMALS = 5


def _round(value: float) -> float:
    return round(float(value), LENGTH_DECIMALS) + 0.0  # no -0.0


def _direction(vector: np.ndarray) -> tuple[float, ...]:
    """``vector`` as a unit direction, rounded to :data:`DIRECTION_DECIMALS` and made unit
    again (an axis-aligned one is then exact)."""
    rounded = np.round(np.asarray(vector, dtype=np.float64), DIRECTION_DECIMALS) + 0.0
    return tuple(float(v) for v in rounded / np.linalg.norm(rounded))


def _origin(element: Any) -> np.ndarray:
    origin = getattr(element, "origin", None)
    return np.eye(4) if origin is None else np.asarray(origin, dtype=np.float64)


def _corners(link: Any, frame: np.ndarray) -> np.ndarray:
    """``(8 K, 3)`` corners of the link's collision boxes and of the boxes around its
    cylinders, in the frame ``frame`` (the link's pose there) maps into."""
    corners = []
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    for collision in link.collisions:
        geometry = collision.geometry
        if geometry.box is not None:
            half = np.asarray(geometry.box.size, dtype=np.float64) / 2.0
        elif geometry.cylinder is not None:
            r = geometry.cylinder.radius
            half = np.array([r, r, geometry.cylinder.length / 2.0])
        else:
            continue
        T = frame @ _origin(collision)
        corners.append((signs * half) @ T[:3, :3].T + T[:3, 3])
    return np.concatenate(corners) if corners else np.zeros((0, 3))


def _cylinder_radius(link: Any) -> float:
    """The largest radius about the link's z axis its collision shapes reach."""
    radius = 0.0
    for collision in link.collisions:
        cylinder = collision.geometry.cylinder
        if cylinder is not None:
            radius = max(radius, cylinder.radius + math.hypot(*_origin(collision)[:2, 3]))
    corners = _corners(link, np.eye(4))
    boxes = [c for c in link.collisions if c.geometry.box is not None]
    if boxes and len(corners):
        radius = max(radius, float(np.hypot(corners[:, 0], corners[:, 1]).max()))
    return radius


class _Tree:
    """The URDF's links and joints as a tree, with every link's pose at joints 0."""

    def __init__(self, urdf: Any, source: str) -> None:
        self.urdf = urdf
        self.source = source
        self.joint_to = {joint.child: joint for joint in urdf.robot.joints}
        roots = [link.name for link in urdf.robot.links if link.name not in self.joint_to]
        if len(roots) != 1:
            raise ConfigError(f"{source}: a hand has one root link (the palm), found {roots}")
        self.palm = roots[0]
        self.links = {link.name: link for link in urdf.robot.links}
        self.pose = {self.palm: np.eye(4)}
        pending = [self.palm]
        while pending:
            parent = pending.pop(0)
            for joint in urdf.robot.joints:
                if joint.parent == parent:
                    self.pose[joint.child] = self.pose[parent] @ _origin(joint)
                    pending.append(joint.child)

    def children(self, link: str) -> list[Any]:
        return [joint for joint in self.urdf.robot.joints if joint.parent == link]

    def below(self, link: str) -> list[str]:
        """``link`` and every link hanging from it."""
        found = [link]
        for joint in self.children(link):
            found += self.below(joint.child)
        return found

    def corners(self, links: Iterable[str]) -> np.ndarray:
        parts = [_corners(self.links[name], self.pose[name]) for name in links]
        return np.concatenate(parts) if parts else np.zeros((0, 3))

    def finger_of(self, link: str) -> str:
        return link.split("_", 1)[0]


def _pad_mount(tree: _Tree, link: str) -> PadMount:
    joint = tree.joint_to[link]
    carrier = joint.parent
    T = tree.pose[link]
    centre, normal, along = T[:3, 3], T[:3, 2], T[:3, 0]
    own = _corners(tree.links[link], np.eye(4))
    if not len(own):
        raise ConfigError(f"{tree.source}: pad link '{link}' has no box collision shape")
    reach = tree.corners(tree.below(carrier)) @ along
    # The carrier's own shapes in the pad's frame: their front along the pad's normal.
    carrier_in_pad = _corners(tree.links[carrier], np.linalg.inv(_origin(joint)))
    front = float(carrier_in_pad[:, 2].max()) if len(carrier_in_pad) else -math.inf
    return PadMount(
        pad=link.removesuffix("_pad"),
        link=link,
        finger=tree.finger_of(carrier),
        centre_m=tuple(_round(v) for v in centre),
        normal=_direction(normal),
        length_m=_round(np.ptp(own[:, 0])),
        width_m=_round(np.ptp(own[:, 1])),
        centre_to_fingertip_m=_round(reach.max() - centre @ along),
        recess_m=_round(max(0.0, -front)),
    )


def _joint_limit(joint: Any) -> float:
    return float(joint.limit.upper) if joint.limit is not None else 0.0


def _bending_finger(tree: _Tree, base: Any, pads: dict[str, PadMount]) -> BendingFinger | None:
    """The finger from its base joint ``base`` when it is a turn-and-bend chain (a knuckle,
    then a proximal and a distal link on revolute joints, each carrying a pad), else None."""
    knuckle = base.child
    chain = [j for j in tree.children(knuckle) if not j.child.endswith("_pad")]
    if len(chain) != 1 or chain[0].type != "revolute":
        return None
    proximal_joint = chain[0]
    proximal = proximal_joint.child
    chain = [j for j in tree.children(proximal) if not j.child.endswith("_pad")]
    if len(chain) != 1 or chain[0].type != "revolute":
        return None
    distal_joint = chain[0]
    distal = distal_joint.child
    proximal_pad = [j for j in tree.children(proximal) if j.child.endswith("_pad")]
    distal_pad = [j for j in tree.children(distal) if j.child.endswith("_pad")]
    if len(proximal_pad) != 1 or len(distal_pad) != 1:
        return None
    name = tree.finger_of(knuckle)
    facing = np.asarray(pads[distal_pad[0].child.removesuffix("_pad")].normal[:2])
    if base.type == "revolute":
        axis_z = (tree.pose[knuckle][:3, :3] @ np.asarray(base.axis, dtype=np.float64))[2]
        spread_sign = int(np.sign(np.round(axis_z, 6)))
    else:
        spread_sign = 0
    proximal_corners = _corners(tree.links[proximal], np.eye(4))
    distal_corners = _corners(tree.links[distal], np.eye(4))
    base_origin = _origin(base)[:3, 3]
    return BendingFinger(
        name=name,
        base_m=(_round(base_origin[0]), _round(base_origin[1])),
        base_depth_m=_round(base_origin[2]),
        spread_sign=spread_sign,
        facing=_direction(facing),
        knuckle_length_m=_round(_origin(proximal_joint)[2, 3]),
        knuckle_radius_m=_round(_cylinder_radius(tree.links[knuckle])),
        proximal_length_m=_round(_origin(distal_joint)[2, 3]),
        distal_length_m=_round(distal_corners[:, 2].max()),
        half_width_m=_round(np.abs(proximal_corners[:, 1]).max()),
        proximal_back_m=_round(proximal_corners[:, 0].min()),
        proximal_pad_offset_m=_round(_origin(proximal_pad[0])[0, 3]),
        distal_back_m=_round(distal_corners[:, 0].min()),
        distal_pad_offset_m=_round(_origin(distal_pad[0])[0, 3]),
        distal_pad_centre_m=_round(_origin(distal_pad[0])[2, 3]),
        bend_limit_rad=_joint_limit(proximal_joint),
    )


def _closing(
    tree: _Tree, bases: list[Any], pads: tuple[PadMount, ...], bending: tuple[BendingFinger, ...]
) -> tuple[ClosingPad, ...]:
    """Each finger's pad nearest its fingertip, closing along its normal's horizontal part
    from its finger's base joint (flat; the caller adds a curved pad's rows)."""
    turning = {finger.name: finger.spread_sign for finger in bending}
    closing = []
    for base in bases:
        finger = tree.finger_of(base.child)
        mounts = [mount for mount in pads if mount.finger == finger]
        if not mounts:
            continue
        mount = min(mounts, key=lambda m: m.centre_to_fingertip_m)
        facing = np.asarray(mount.normal[:2])
        if np.linalg.norm(facing) < 1e-6:
            continue  # a pad facing along the approach closes on nothing
        origin = _origin(base)[:3, 3]
        closing.append(
            ClosingPad(
                mount.pad,
                (_round(origin[0]), _round(origin[1])),
                _direction(facing),
                turning.get(finger, 0),
            )
        )
    return tuple(closing)


def read_hand_geometry(path: str | Path) -> HandGeometry:
    """The hand described by the URDF at ``path``, read by the module's convention.

    Raises:
        ConfigError: the file is missing or not a URDF, it has no single root link, or
            no link named ``<pad>_pad``.
    """
    import yourdfpy

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such hand URDF")
    try:
        urdf = yourdfpy.URDF.load(
            str(path), build_scene_graph=False, load_meshes=False, load_collision_meshes=False
        )
    except Exception as error:  # yourdfpy raises lxml's and its own errors alike
        raise ConfigError(f"{path}: not a readable URDF ({error})") from error
    tree = _Tree(urdf, str(path))
    pad_links = [link for link in tree.links if link.endswith("_pad")]
    if not pad_links:
        raise ConfigError(f"{path}: no pad link (a link named '<pad>_pad')")
    pads = tuple(_pad_mount(tree, link) for link in pad_links)
    by_name = {mount.pad: mount for mount in pads}
    bases = tree.children(tree.palm)
    housing_corners = _corners(tree.links[tree.palm], np.eye(4))
    if not len(housing_corners):
        raise ConfigError(f"{path}: the palm '{tree.palm}' has no collision shape")
    housing = Housing(
        depth_m=_round(housing_corners[:, 2].max()),
        half_length_m=_round(np.abs(housing_corners[:, 0]).max()),
        half_width_m=_round(np.abs(housing_corners[:, 1]).max()),
        radius_m=_round(_cylinder_radius(tree.links[tree.palm])),
    )
    fingers = tuple(tree.finger_of(base.child) for base in bases)
    everything = tree.corners(name for name in tree.links if name != tree.palm)
    jaws = [base for base in bases if base.type == "prismatic"]
    jaw_half_width = jaw_travel = jaw_speed = gap = 0.0
    if jaws and len(jaws) == len(bases):
        jaw_links = [name for base in jaws for name in tree.below(base.child)]
        jaw_corners = tree.corners(n for n in jaw_links if not n.endswith("_pad"))
        jaw_half_width = _round(np.abs(jaw_corners[:, 1]).max())
        closing_pads = _closing(tree, bases, pads, ())
        surfaces = [np.asarray(by_name[c.pad].centre_m) @ (*c.facing, 0.0) for c in closing_pads]
        gap = -sum(surfaces)  # each pad's surface before the centre plane at joints 0
        jaw_travel = _round(gap + sum(_joint_limit(base) for base in jaws))
        jaw_speed = min(float(base.limit.velocity or 0.0) for base in jaws)
    bending = tuple(
        finger
        for finger in (_bending_finger(tree, base, by_name) for base in bases)
        if finger is not None
    )
    return HandGeometry(
        urdf=path.name,
        fingers=fingers,
        pads=pads,
        housing=housing,
        fingertip_depth_m=_round(everything[:, 2].max()),
        jaw_half_width_m=jaw_half_width,
        jaw_travel_m=jaw_travel,
        jaw_closed_m=_round(gap),
        jaws=tuple(base.name for base in jaws) if jaw_travel else (),
        jaw_speed_m_s=jaw_speed,
        bending=bending,
        closing=_closing(tree, bases, pads, bending),
    )


def hand_urdf_path(urdf: str | Path) -> Path:
    """Where the hand URDF ``urdf`` is: the path itself when it exists (relative to the
    working directory), else the file of that name in ``robots/``, absolute."""
    from robots import ROOT

    path = Path(urdf)
    return (path if path.exists() else ROOT / path).resolve()


@functools.cache
def hand_geometry(urdf: str) -> HandGeometry:
    """The :class:`HandGeometry` of the hand ``urdf`` (:func:`hand_urdf_path`), read once
    (:func:`read_hand_geometry`)."""
    return read_hand_geometry(hand_urdf_path(urdf))


@dataclass(frozen=True)
class PadGeometry:
    """A pad's taxel layout plus the shape of its surface (see
    :func:`pipeline.geometry.pad_layout.pad_grid`): the tactile sensor's part of a pad,
    which the URDF does not describe."""

    layout: PadLayout
    curved_rows: int = 0
    curve_radius_m: float = math.inf


def gripper_spec_from_urdf(
    name: str, urdf: str | Path, pads: Sequence[PadGeometry], max_aperture_m: float | None = None
) -> GripperSpec:
    """The :class:`GripperSpec` named ``name`` of the hand ``urdf`` (:func:`hand_geometry`):
    its fingers, fingertip depth, closing pads and geometry read from the URDF, and
    its taxel grids ``pads`` (in that order; a pad's closing rows curve as its
    :class:`PadGeometry` says). ``max_aperture_m`` defaults to the jaws' travel (a
    parallel gripper's; a bending hand's follows from its kinematics)."""
    geometry = hand_geometry(str(urdf))
    curves = {p.layout.name: p for p in pads if p.curved_rows}
    closing = tuple(
        dataclasses.replace(
            c,
            curved_rows=curves[c.pad].curved_rows,
            curve_radius_m=curves[c.pad].curve_radius_m,
        )
        if c.pad in curves
        else c
        for c in geometry.closing
    )
    return GripperSpec(
        name,
        len(geometry.fingers),
        geometry.jaw_travel_m if max_aperture_m is None else max_aperture_m,
        tuple(p.layout for p in pads),
        geometry.fingertip_depth_m,
        closing,
        geometry,
    )
