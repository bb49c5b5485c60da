"""The MuJoCo model of a scene: the table, one object and at most one hand, built as an
``MjSpec`` and compiled.

The robot frame ``R`` is MuJoCo's world frame: z up, the table top is the plane
``z = table_height_m``. The object is a free body whose frame is its mesh's frame. It
carries two kinds of geoms: its mesh itself, which only the camera's rays see (group
:data:`OBJECT_VISUAL_GROUP`, no contacts), and convex collision parts (group
:data:`OBJECT_COLLISION_GROUP`): the mesh for a convex mesh (MuJoCo collides a mesh geom as
its convex hull), else the parts of :func:`pipeline.sim.collision.convex_decomposition`,
as in the PyBullet world. Its mass properties are those of a uniform solid
(:func:`pipeline.sim.bodies.mass_properties`).

The hand is compiled from its URDF in ``robots/`` (the one description both engines
read), its links kept as bodies (``fusestatic`` off) so that each pad is a body, their
names prefixed with :data:`HAND_PREFIX`. Its palm is a free body welded to a mocap body,
the target :meth:`pipeline.sim.mujoco.hand.MujocoHand.move_to` sets (a stiff spring, like
the PyBullet world's base constraint); gravity is compensated on every hand body, as the
arm carrying a real hand would. Each moving joint has a position servo whose force cap the
grasp sets (:meth:`~pipeline.sim.mujoco.hand.MujocoHand.command`). The hand's links do
not collide with each other (PyBullet loads URDFs without self-collision).

Friction: MuJoCo takes a contact's friction from the geom of higher ``priority``; the
table and the hand have the higher one and carry the products PyBullet forms from its
per-body coefficients (table and hand links 0.5, pads 1.0, times the object's): the same
coefficients in both engines.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import trimesh

from pipeline.errors import InputError
from pipeline.sim.bodies import OBJECT_RGBA, TABLE_HALF_EXTENTS_M, TABLE_RGBA, mass_properties
from pipeline.sim.collision import convex_decomposition, read_convex_parts
from pipeline.sim.hand_models import PARK_POSITION_M, hand_model
from robots import ROOT as ROBOTS_ROOT

#: MuJoCo's time step (s). The grasp sequence steps at 1/240 s; each of its steps is this
#: many MuJoCo steps (:meth:`pipeline.sim.mujoco.world.MujocoPhysics.step`): four make
#: the contact and weld springs below stiff enough for the pads to sink less than 0.1 mm.
TIMESTEP_S = 1.0 / 960.0
#: Contact and weld stiffness: the time constant MuJoCo allows at its stiffest (twice
#: the time step), critically damped; and the impedance (MuJoCo's ``solimp``): 0.95 of
#: the constraint force at once, 0.99 at 1 mm of penetration.
SOLREF = (2.0 * TIMESTEP_S, 1.0)
SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
#: Rolling resistance of an object on the table (m), as in the PyBullet world.
ROLLING_FRICTION_M = 1e-4
#: Friction PyBullet gives a body it is not told otherwise, and a pad (times the object's).
DEFAULT_FRICTION = 0.5
PAD_FRICTION = 1.0

#: Geom groups: which geoms each ray query sees (the camera: table, object mesh, hand;
#: taxel probes: table and object collision parts).
TABLE_GROUP = 0
OBJECT_VISUAL_GROUP = 1
HAND_GROUP = 2
OBJECT_COLLISION_GROUP = 3
#: Collision bits: the hand collides with the table and the object, not with itself.
WORLD_BIT = 1
HAND_BIT = 2

OBJECT_BODY = "object"
HAND_TARGET_BODY = "hand_target"
HAND_PREFIX = "hand/"

#: Position servo stiffness per unit of effort limit: the full effort is reached at 5 mm
#: (prismatic) or 0.05 rad (revolute) from the target, so a finger whose target is
#: squeezed past the surface (:class:`pipeline.sim.hand_models.FingerDrive`) presses with
#: its force cap; critically damped (MuJoCo's ``dampratio``).
SERVO_STIFFNESS_PER_EFFORT = {
    mujoco.mjtJoint.mjJNT_SLIDE: 1.0 / 0.005,
    mujoco.mjtJoint.mjJNT_HINGE: 1.0 / 0.05,
}
#: Rotor inertia added to each hand joint (kg, kg m^2), what a geared drive reflects: it
#: keeps the stiff servos of the light finger links stable at :data:`TIMESTEP_S`.
ARMATURE = {mujoco.mjtJoint.mjJNT_SLIDE: 0.05, mujoco.mjtJoint.mjJNT_HINGE: 2e-4}


@dataclass(frozen=True)
class ObjectBody:
    """What the model needs of the object, built once per scene.

    Attributes:
        mesh: its surface in its own frame (m); the camera sees it.
        parts: ``(K_i, 3)`` vertices of each convex collision part, same frame.
        mass_kg, friction: as the :class:`~pipeline.types.SceneObject` gives them.
        center_mass, principal_quat_xyzw, moments: uniform-solid mass properties.
    """

    mesh: trimesh.Trimesh
    parts: tuple[np.ndarray, ...]
    mass_kg: float
    friction: float
    center_mass: np.ndarray
    principal_quat_xyzw: np.ndarray
    moments: np.ndarray

    @classmethod
    def from_mesh(
        cls, mesh: trimesh.Trimesh, mass_kg: float, friction: float, vhacd_resolution: int
    ) -> ObjectBody:
        """Collision parts as the PyBullet world makes them: the mesh itself when it is
        convex, else its cached convex decomposition."""
        if mass_kg <= 0:
            raise InputError(f"object mass must be positive, got {mass_kg} kg")
        if len(mesh.faces) == 0:
            raise InputError("object mesh has no faces")
        if mesh.is_convex:
            parts = (np.asarray(mesh.vertices, dtype=np.float64),)
        else:
            parts = tuple(read_convex_parts(convex_decomposition(mesh, vhacd_resolution)))
        center_mass, quat, moments = mass_properties(mesh, mass_kg)
        return cls(mesh, parts, mass_kg, friction, center_mass, quat, moments)

    @property
    def lowest_z_m(self) -> float:
        """The lowest point of the collision parts, object frame: what rests on the table
        (a part may reach a little below the mesh)."""
        return float(min(part[:, 2].min() for part in self.parts))


def _wxyz(quaternion_xyzw: np.ndarray) -> list[float]:
    x, y, z, w = (float(v) for v in quaternion_xyzw)
    return [w, x, y, z]


def _hand_spec(gripper: str) -> mujoco.MjSpec:
    """The hand's URDF compiled by MuJoCo's URDF reader, every link kept as a body."""
    text = (ROBOTS_ROOT / hand_model(gripper).urdf).read_text()
    extension = '<mujoco><compiler fusestatic="false" discardvisual="true"/></mujoco></robot>'
    return mujoco.MjSpec.from_string(text.replace("</robot>", extension))


def _set_contact(geom: mujoco.MjsGeom, group: int, contype: int, conaffinity: int) -> None:
    geom.group = group
    geom.contype = contype
    geom.conaffinity = conaffinity
    geom.solref = SOLREF
    geom.solimp = SOLIMP
    geom.margin = 0.0


def build_model(
    body: ObjectBody,
    position_m: np.ndarray,
    quaternion_xyzw: np.ndarray,
    table_height_m: float,
    gripper: str | None,
) -> mujoco.MjModel:
    """Compile the scene: the table, the object at ``position_m``/``quaternion_xyzw``
    (its frame in R), and the hand ``gripper`` parked at
    :data:`~pipeline.sim.hand_models.PARK_POSITION_M` (None: no hand)."""
    spec = mujoco.MjSpec()
    spec.option.timestep = TIMESTEP_S
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.gravity = [0.0, 0.0, -9.81]
    world = spec.worldbody

    half = TABLE_HALF_EXTENTS_M
    table = world.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(half),
        pos=[0.0, 0.0, table_height_m - half[2]],
        rgba=list(TABLE_RGBA),
    )
    _set_contact(table, TABLE_GROUP, WORLD_BIT, WORLD_BIT | HAND_BIT)
    table.priority = 1
    table.friction = [DEFAULT_FRICTION * body.friction, 0.0, ROLLING_FRICTION_M]
    table.condim = 6  # sliding, spinning and rolling friction

    obj = world.add_body(
        name=OBJECT_BODY, pos=list(map(float, position_m)), quat=_wxyz(quaternion_xyzw)
    )
    obj.add_freejoint(name=OBJECT_BODY)
    obj.explicitinertial = True
    obj.mass = body.mass_kg
    obj.ipos = list(map(float, body.center_mass))
    obj.iquat = _wxyz(body.principal_quat_xyzw)
    obj.inertia = list(map(float, body.moments))
    spec.add_mesh(
        name="object_surface",
        uservert=np.asarray(body.mesh.vertices, dtype=np.float64).ravel().tolist(),
        userface=np.asarray(body.mesh.faces, dtype=np.int64).ravel().tolist(),
        inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL,
    )
    surface = obj.add_geom(
        name="object_surface",
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname="object_surface",
        rgba=list(OBJECT_RGBA),
    )
    _set_contact(surface, OBJECT_VISUAL_GROUP, 0, 0)
    for index, part in enumerate(body.parts):
        name = f"object_part_{index}"
        spec.add_mesh(name=name, uservert=part.ravel().tolist())
        geom = obj.add_geom(
            name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, rgba=list(OBJECT_RGBA)
        )
        _set_contact(geom, OBJECT_COLLISION_GROUP, WORLD_BIT, WORLD_BIT | HAND_BIT)
        geom.friction = [body.friction, 0.0, 0.0]

    if gripper is not None:
        _add_hand(spec, gripper, body.friction)
    try:
        return spec.compile()
    except ValueError as error:  # MuJoCo's compiler reports a bad mesh this way
        raise InputError(f"MuJoCo cannot compile the scene: {error}") from error


def _add_hand(spec: mujoco.MjSpec, gripper: str, object_friction: float) -> None:
    """Attach the hand ``gripper`` to ``spec`` (see the module doc)."""
    model = hand_model(gripper)
    pad_links = {HAND_PREFIX + pad.layout.link for pad in model.pads}
    park = [float(v) for v in PARK_POSITION_M]
    target = spec.worldbody.add_body(name=HAND_TARGET_BODY, mocap=True, pos=park)
    frame = spec.worldbody.add_frame(pos=park)
    palm = frame.attach_body(_hand_spec(gripper).body("palm"), HAND_PREFIX, "")
    palm.add_freejoint(name=HAND_PREFIX + "base")
    weld = spec.add_equality(
        type=mujoco.mjtEq.mjEQ_WELD,
        name1=target.name,
        name2=palm.name,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
    )
    # anchor (3), the palm's pose relative to the target (position 3, quaternion 4: the
    # identity), torque scale, unused
    weld.data = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0])
    weld.solref = SOLREF
    for hand_body in [palm, *palm.find_all(mujoco.mjtObj.mjOBJ_BODY)]:
        hand_body.gravcomp = 1.0
    for geom in palm.find_all(mujoco.mjtObj.mjOBJ_GEOM):
        _set_contact(geom, HAND_GROUP, HAND_BIT, WORLD_BIT)
        geom.priority = 1
        on_pad = geom.parent.name in pad_links
        geom.friction = [(PAD_FRICTION if on_pad else DEFAULT_FRICTION) * object_friction, 0, 0]
    for joint in palm.find_all(mujoco.mjtObj.mjOBJ_JOINT):
        if joint.type not in SERVO_STIFFNESS_PER_EFFORT:
            continue
        joint.armature = ARMATURE[joint.type]
        effort = float(joint.actfrcrange[1])
        actuator = spec.add_actuator(
            name=joint.name, target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT
        )
        actuator.set_to_position(kp=effort * SERVO_STIFFNESS_PER_EFFORT[joint.type], dampratio=1.0)
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-effort, effort]
        actuator.ctrlrange = list(map(float, joint.range))
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
