"""The PyBullet scene: a DIRECT-mode physics client with gravity, a table, and objects.

The robot frame ``R`` is PyBullet's world frame: z up, the table top is the plane
``z = table_height_m``. Objects are meshes in metres in their own frame (base on ``z = 0``,
centred in x, y) placed upright on the table at a planar pose ``(x, y, yaw)``.

Collision geometry: a convex mesh is used as it is (PyBullet builds its hull); a non-convex
one is split into convex parts (:mod:`pipeline.sim.collision`). The visual shape is the mesh
itself.
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType

import numpy as np
import pybullet
import trimesh
from scipy.spatial.transform import Rotation

from pipeline.errors import InputError
from pipeline.sim.bodies import (
    MAX_SETTLE_STEPS,
    OBJECT_RGBA,
    REST_SPEED_M_S,
    REST_SPIN_RAD_S,
    SETTLE_STEPS,
    TABLE_HALF_EXTENTS_M,
    TABLE_RGBA,
    mass_properties,
)
from pipeline.sim.collision import convex_decomposition
from pipeline.types import ObjectPose

#: Bullet collision margin of the table and objects (m). Bullet's default (about 1 mm on
#: convex hulls) would leave objects floating that high above the table.
COLLISION_MARGIN_M = 1e-4

#: Rolling resistance of an object on the table (m): the lever arm of the torque that
#: resists rolling, per unit normal force (Bullet's ``rollingFriction``; hard plastic on a
#: table has a rolling coefficient of about 0.003, times a 30 mm radius). Without it a
#: round object lying on its side, its convex hull resting on an edge, starts to roll
#: and the solver keeps adding speed: a lying 56 mm cylinder went 120 mm in 2 s.
ROLLING_FRICTION_M = 1e-4

#: PyBullet's limits on a mesh handed over as arrays: the vertices of a convex collision
#: shape, and the triangles of a visual shape (524,288 indices). A mesh over them is
#: simplified for the simulator (:func:`within_faces`); the ground truth keeps every face.
MAX_CONVEX_VERTICES = 131_072
MAX_VISUAL_FACES = 174_762


def _quaternion_yaw(yaw_rad: float) -> list[float]:
    return Rotation.from_euler("z", yaw_rad).as_quat().tolist()


class Scene:
    """A PyBullet DIRECT client holding a table and any number of objects.

    Use as a context manager (or call :meth:`close`) to disconnect the client. The physics is
    deterministic: same calls, same results (``deterministicOverlappingPairs`` is on).

    Args:
        table_height_m: z of the table top in the robot frame (m).
        timestep_s: physics time step (s).
        vhacd_resolution: voxel count V-HACD uses for non-convex meshes.
        client: a connected, empty DIRECT client to build the scene in (just reset with
            ``pybullet.resetSimulation``); it stays the caller's: :meth:`close` leaves it
            connected. None connects a new client that :meth:`close` disconnects.
    """

    def __init__(
        self,
        table_height_m: float = 0.0,
        timestep_s: float = 1.0 / 240.0,
        vhacd_resolution: int = 100_000,
        client: int | None = None,
    ) -> None:
        self.table_height_m = float(table_height_m)
        self.timestep_s = float(timestep_s)
        self.vhacd_resolution = vhacd_resolution
        self._owns_client = client is None
        self.client = pybullet.connect(pybullet.DIRECT) if client is None else client
        pybullet.setGravity(0.0, 0.0, -9.81, physicsClientId=self.client)
        pybullet.setTimeStep(self.timestep_s, physicsClientId=self.client)
        pybullet.setPhysicsEngineParameter(
            deterministicOverlappingPairs=1, physicsClientId=self.client
        )
        self.table_id = self._add_table()

    def __enter__(self) -> Scene:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Disconnect the PyBullet client if the scene connected it (idempotent)."""
        if self._owns_client and self.client >= 0 and pybullet.isConnected(self.client):
            pybullet.disconnect(self.client)
        self.client = -1

    def _add_table(self) -> int:
        half = TABLE_HALF_EXTENTS_M
        collision = pybullet.createCollisionShape(
            pybullet.GEOM_BOX, halfExtents=half, physicsClientId=self.client
        )
        visual = pybullet.createVisualShape(
            pybullet.GEOM_BOX, halfExtents=half, rgbaColor=TABLE_RGBA, physicsClientId=self.client
        )
        table = pybullet.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=collision,
            baseVisualShapeIndex=visual,
            basePosition=(0.0, 0.0, self.table_height_m - half[2]),
            physicsClientId=self.client,
        )
        pybullet.changeDynamics(
            table, -1, collisionMargin=COLLISION_MARGIN_M, physicsClientId=self.client
        )
        return table

    def _collision_shape(self, mesh: trimesh.Trimesh) -> int:
        if mesh.is_convex:
            vertices = mesh.vertices
            if len(vertices) > MAX_CONVEX_VERTICES:
                # A closed mesh has about half as many vertices as triangles.
                vertices = within_faces(mesh.convex_hull, MAX_CONVEX_VERTICES).vertices
            return pybullet.createCollisionShape(
                pybullet.GEOM_MESH,
                vertices=np.asarray(vertices).tolist(),
                physicsClientId=self.client,
            )
        parts = convex_decomposition(mesh, self.vhacd_resolution)
        return pybullet.createCollisionShape(
            pybullet.GEOM_MESH, fileName=str(parts), physicsClientId=self.client
        )

    def add_object(
        self,
        mesh: trimesh.Trimesh,
        mass_kg: float,
        friction: float,
        x_m: float = 0.0,
        y_m: float = 0.0,
        yaw_rad: float = 0.0,
        rgba: tuple[float, float, float, float] = OBJECT_RGBA,
    ) -> int:
        """Add a rigid object standing upright on the table; return its body id.

        ``mesh`` is in metres in the object frame; the frame's origin is put at ``(x_m, y_m)``
        rotated by ``yaw_rad`` about +z, at the height where the collision geometry touches
        the table top (the mesh's lowest point, up to the convex decomposition's accuracy).
        ``friction`` is the lateral Coulomb coefficient; the object resists rolling with
        :data:`ROLLING_FRICTION_M`. Mass properties are those of a uniform solid.
        """
        if mass_kg <= 0:
            raise InputError(f"object mass must be positive, got {mass_kg} kg")
        if len(mesh.faces) == 0:
            raise InputError("object mesh has no faces")
        collision = self._collision_shape(mesh)
        seen = within_faces(mesh, MAX_VISUAL_FACES)
        visual = pybullet.createVisualShape(
            pybullet.GEOM_MESH,
            vertices=np.asarray(seen.vertices).tolist(),
            indices=np.asarray(seen.faces).reshape(-1).tolist(),
            rgbaColor=rgba,
            physicsClientId=self.client,
        )
        center_mass, principal_axes, moments = mass_properties(mesh, mass_kg)
        z_base = self.table_height_m - float(mesh.bounds[0][2])
        body = pybullet.createMultiBody(
            baseMass=mass_kg,
            baseCollisionShapeIndex=collision,
            baseVisualShapeIndex=visual,
            basePosition=(x_m, y_m, z_base),
            baseOrientation=_quaternion_yaw(yaw_rad),
            baseInertialFramePosition=center_mass.tolist(),
            baseInertialFrameOrientation=principal_axes.tolist(),
            physicsClientId=self.client,
        )
        pybullet.changeDynamics(
            body,
            -1,
            lateralFriction=friction,
            rollingFriction=ROLLING_FRICTION_M,
            localInertiaDiagonal=moments.tolist(),
            collisionMargin=COLLISION_MARGIN_M,
            physicsClientId=self.client,
        )
        self._rest_on_table(body)
        return body

    def add_urdf(
        self, path: str | Path, x_m: float = 0.0, y_m: float = 0.0, yaw_rad: float = 0.0
    ) -> int:
        """Load a user URDF as the object, its base frame at ``(x_m, y_m)`` rotated by
        ``yaw_rad``, lifted so its lowest point rests on the table; return its body id."""
        path = Path(path)
        if not path.is_file():
            raise InputError(f"object URDF not found: {path}")
        try:
            body = pybullet.loadURDF(
                str(path),
                basePosition=(x_m, y_m, 0.0),
                baseOrientation=_quaternion_yaw(yaw_rad),
                physicsClientId=self.client,
            )
        except pybullet.error as error:
            raise InputError(f"cannot load object URDF {path}: {error}") from error
        lowest_z = min(
            pybullet.getAABB(body, link, physicsClientId=self.client)[0][2]
            for link in range(-1, pybullet.getNumJoints(body, physicsClientId=self.client))
        )
        self._lift(body, self.table_height_m - lowest_z)
        self._rest_on_table(body)
        return body

    def _lift(self, body: int, dz_m: float) -> None:
        pose = self.object_pose(body)
        position = pose.position_m + np.array([0.0, 0.0, dz_m])
        self.set_object_pose(body, ObjectPose(position, pose.quaternion_xyzw))

    def _rest_on_table(self, body: int) -> None:
        """Move ``body`` vertically so its collision geometry just touches the table (the
        AABB is padded and convex decompositions can reach below the mesh)."""
        closest = pybullet.getClosestPoints(
            body, self.table_id, distance=1.0, physicsClientId=self.client
        )
        if closest:
            self._lift(body, -min(point[8] for point in closest))

    def object_pose(self, body: int) -> ObjectPose:
        """Pose of the body's base *link* frame (the mesh or URDF origin), not of its centre
        of mass, which is what PyBullet reports."""
        position, orientation = pybullet.getBasePositionAndOrientation(
            body, physicsClientId=self.client
        )
        local_position, local_orientation = pybullet.getDynamicsInfo(
            body, -1, physicsClientId=self.client
        )[3:5]
        inverse = pybullet.invertTransform(local_position, local_orientation)
        link_position, link_orientation = pybullet.multiplyTransforms(
            position, orientation, *inverse
        )
        return ObjectPose(np.array(link_position), np.array(link_orientation))

    def set_object_pose(self, body: int, pose: ObjectPose) -> None:
        """Teleport the body so its base link frame is at ``pose`` (velocities zeroed)."""
        local_position, local_orientation = pybullet.getDynamicsInfo(
            body, -1, physicsClientId=self.client
        )[3:5]
        position, orientation = pybullet.multiplyTransforms(
            pose.position_m.tolist(),
            pose.quaternion_xyzw.tolist(),
            local_position,
            local_orientation,
        )
        pybullet.resetBasePositionAndOrientation(
            body, position, orientation, physicsClientId=self.client
        )
        pybullet.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)

    def settle(self, body: int) -> None:
        """Let ``body`` settle on the table: :data:`SETTLE_STEPS`, then more while it still
        moves faster than :data:`REST_SPEED_M_S` or turns faster than
        :data:`REST_SPIN_RAD_S`, up to :data:`MAX_SETTLE_STEPS` more."""
        self.step(SETTLE_STEPS)
        for _ in range(MAX_SETTLE_STEPS // SETTLE_STEPS):
            linear, angular = pybullet.getBaseVelocity(body, physicsClientId=self.client)
            if (
                np.linalg.norm(linear) < REST_SPEED_M_S
                and np.linalg.norm(angular) < REST_SPIN_RAD_S
            ):
                return
            self.step(SETTLE_STEPS)

    def step(self, steps: int = 1) -> None:
        """Advance the physics by ``steps`` time steps."""
        for _ in range(steps):
            pybullet.stepSimulation(physicsClientId=self.client)


def within_faces(mesh: trimesh.Trimesh, max_faces: int) -> trimesh.Trimesh:
    """``mesh`` itself when it has at most ``max_faces`` triangles, else its quadric
    decimation to that many (open3d): on a scan or a finely tessellated solid that moves
    the surface by far less than the depth sensor's noise."""
    if len(mesh.faces) <= max_faces:
        return mesh
    from pipeline.io.open3d_loader import open3d

    o3d = open3d()
    dense = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(mesh.vertices, dtype=np.float64)),
        o3d.utility.Vector3iVector(np.asarray(mesh.faces, dtype=np.int32)),
    )
    simple = dense.simplify_quadric_decimation(target_number_of_triangles=max_faces)
    return trimesh.Trimesh(np.asarray(simple.vertices), np.asarray(simple.triangles))
