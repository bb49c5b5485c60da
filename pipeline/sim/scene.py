"""The PyBullet scene: a DIRECT-mode physics client with gravity, a table, and objects.

The robot frame ``R`` is PyBullet's world frame: z up, the table top is the plane
``z = table_height_m``. Objects are meshes in metres in their own frame (base on ``z = 0``,
centred in x, y) placed upright on the table at a planar pose ``(x, y, yaw)``.

Collision geometry: a convex mesh is used as it is (PyBullet builds its hull); a non-convex
one is split into convex parts with PyBullet's V-HACD, cached on disk under
``$SYMFUSE_CACHE`` (default ``~/.cache/symfuse``) keyed by a hash of the mesh and the
decomposition settings, so each shape is decomposed once per machine. The visual shape is the
mesh itself.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from types import TracebackType

import numpy as np
import pybullet
import trimesh
from scipy.spatial.transform import Rotation

from pipeline.errors import InputError
from pipeline.metrics import mesh_occupancy, point_to_mesh_distances
from pipeline.types import ObjectPose

from . import native_output_silenced

#: Half-extents of the table box (m): 2 m x 2 m, 5 cm thick.
TABLE_HALF_EXTENTS_M = (1.0, 1.0, 0.025)
TABLE_RGBA = (0.55, 0.45, 0.35, 1.0)
OBJECT_RGBA = (0.2, 0.45, 0.8, 1.0)
#: Bullet collision margin of the table and objects (m). Bullet's default (about 1 mm on
#: convex hulls) would leave objects floating that high above the table.
COLLISION_MARGIN_M = 1e-4
#: How far (m) a convex part of a non-convex object's collision geometry may stick out of
#: the true surface. Taxels in contact lie on the collision geometry, so this bounds their
#: offset from the surface the estimator is measured against.
HULL_TOLERANCE_M = 2e-4
#: Surface samples of a non-convex mesh the refined parts are built from, and the most
#: times a part may be halved.
HULL_SAMPLES = 40_000
HULL_MAX_SPLITS = 6


def cache_dir() -> Path:
    """Directory for cached convex decompositions: ``$SYMFUSE_CACHE`` or ``~/.cache/symfuse``."""
    root = os.environ.get("SYMFUSE_CACHE") or Path.home() / ".cache" / "symfuse"
    return Path(root)


def mesh_hash(mesh: trimesh.Trimesh) -> str:
    """A stable hex digest of a mesh's vertices (float64) and faces (int64)."""
    digest = hashlib.sha256()
    digest.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    return digest.hexdigest()


def convex_decomposition(mesh: trimesh.Trimesh, resolution: int) -> Path:
    """Path of an OBJ file holding convex parts of ``mesh`` (one OBJ object per part).

    Computed on first use with ``pybullet.vhacd`` and cached; later calls with the same mesh
    and settings return the cached file. V-HACD builds its hulls from a voxelisation, which
    puts their vertices up to about a voxel (2-3 mm for a 10 cm object) outside the surface;
    for a watertight mesh each such vertex is moved to the closest surface point and the
    part's hull rebuilt ("shrink-wrapping", as V-HACD 4 does), so objects neither float
    above the table nor meet the fingers early. Shrink-wrapping fixes the vertices, not the
    faces: a hull still bridges any concavity smaller than a voxel (a lid 1.5 mm wider than
    its can), so the fingers would stop that far outside the true surface and every taxel
    in contact would lie there. Each part is therefore also refined
    (:func:`_faithful_hulls`) until no hull sticks out of the mesh by more than
    ``HULL_TOLERANCE_M``.
    """
    directory = cache_dir() / "vhacd"
    key = f"{mesh_hash(mesh)[:32]}_r{resolution}_refined{HULL_TOLERANCE_M * 1e6:.0f}um"
    path = directory / f"{key}.obj"
    if path.is_file():
        return path
    directory.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=directory) as scratch:
        source = Path(scratch) / "source.obj"
        result = Path(scratch) / "parts.obj"
        mesh.export(source)
        with native_output_silenced(1):
            pybullet.vhacd(
                str(source),
                str(result),
                str(Path(scratch) / "vhacd.log"),
                resolution=resolution,
                maxNumVerticesPerCH=64,
            )
        parts = _read_obj_parts(result) if result.is_file() else []
        if not parts:
            raise InputError(f"convex decomposition of mesh {key} produced no parts")
        if mesh.is_watertight:
            parts = _faithful_hulls([_shrink_wrap(part, mesh) for part in parts], mesh)
        staged = Path(scratch) / "wrapped.obj"
        _write_obj_parts(staged, parts)
        os.replace(staged, path)
    return path


def _read_obj_parts(path: Path) -> list[np.ndarray]:
    """Vertices ``(K, 3)`` of each ``o`` object in an OBJ file (faces are not needed: every
    part is convex and rebuilt as a hull)."""
    parts: list[list[list[float]]] = []
    for line in path.read_text().splitlines():
        if line.startswith("o "):
            parts.append([])
        elif line.startswith("v ") and parts:
            parts[-1].append([float(value) for value in line.split()[1:4]])
    return [np.array(part) for part in parts if len(part) >= 4]


def _shrink_wrap(vertices: np.ndarray, mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Convex hull of ``vertices`` after moving those outside ``mesh`` onto its surface."""
    outside = trimesh.proximity.signed_distance(mesh, vertices) < 0.0  # trimesh: outside < 0
    wrapped = vertices.copy()
    if outside.any():
        wrapped[outside] = trimesh.proximity.closest_point(mesh, vertices[outside])[0]
    return trimesh.convex.convex_hull(wrapped)


def _outside_distances(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """``(N,)`` how far (m) each point lies outside the watertight ``mesh`` (0 inside)."""
    distances = point_to_mesh_distances(points, mesh.vertices, mesh.faces)
    return np.where(mesh_occupancy(points, mesh.vertices, mesh.faces), 0.0, distances)


def _faithful_hulls(hulls: list[trimesh.Trimesh], mesh: trimesh.Trimesh) -> list[trimesh.Trimesh]:
    """Convex parts covering the watertight ``mesh`` that stick out of it by at most
    ``HULL_TOLERANCE_M`` (as far as ``HULL_MAX_SPLITS`` halvings get).

    Dense surface samples are shared out among the parts (each goes to the hull it lies
    in, or the nearest), each part becomes the hull of its samples, and a hull that sticks
    out too far is cut in two (:func:`_split_where_hull_bulges`) and both halves refined.
    """
    rng = np.random.default_rng(0)
    samples, _ = trimesh.sample.sample_surface(mesh, HULL_SAMPLES, seed=rng)
    points = np.concatenate([samples, mesh.vertices])
    outside = np.stack(
        [
            np.where(
                hull.contains(points),
                0.0,
                point_to_mesh_distances(points, hull.vertices, hull.faces),
            )
            for hull in hulls
        ]
    )
    owner = np.argmin(outside, axis=0)
    refined: list[trimesh.Trimesh] = []
    for index in range(len(hulls)):
        refined.extend(_split_where_hull_bulges(points[owner == index], mesh, HULL_MAX_SPLITS))
    return refined


def _hull_bulge(
    points: np.ndarray, mesh: trimesh.Trimesh
) -> tuple[trimesh.Trimesh, float, np.ndarray]:
    """The hull of ``points``, how far (m) it sticks out of ``mesh`` at most, and where."""
    hull = trimesh.convex.convex_hull(points)
    probes, _ = trimesh.sample.sample_surface(hull, 4000, seed=np.random.default_rng(0))
    probes = np.concatenate([probes, hull.vertices])
    outside = _outside_distances(probes, mesh)
    worst = int(np.argmax(outside))
    return hull, float(outside[worst]), probes[worst]


def _split_where_hull_bulges(
    points: np.ndarray, mesh: trimesh.Trimesh, splits_left: int
) -> list[trimesh.Trimesh]:
    """Hulls of ``points`` (samples of the mesh surface): one, or, where it sticks out of
    ``mesh`` by more than ``HULL_TOLERANCE_M``, those of the two halves on either side of
    a plane through the surface point nearest to the worst bulge.

    Of the three planes normal to the principal axes of ``points``, the one whose halves
    bulge least is taken: a hull that bridges a step, such as a lid wider than its can, is
    cut at the step.
    """
    if len(points) < 4 or np.linalg.matrix_rank(points - points[0], tol=1e-9) < 3:
        return []
    hull, bulge, worst = _hull_bulge(points, mesh)
    if hull.volume < 1e-12:  # a sliver of coplanar samples holds nothing up
        return []
    if splits_left == 0 or bulge <= HULL_TOLERANCE_M:
        return [hull]
    nearest = trimesh.proximity.closest_point(mesh, worst[None])[0][0]
    centred = points - points.mean(axis=0)
    best: tuple[float, list[np.ndarray]] | None = None
    for axis in np.linalg.eigh(centred.T @ centred)[1].T:
        height = (points - nearest) @ axis
        halves = [points[height > 0.0], points[height <= 0.0]]
        if min(len(h) for h in halves) < 4:
            continue
        worst_half = max(_hull_bulge(h, mesh)[1] for h in halves)
        if best is None or worst_half < best[0]:
            best = (worst_half, halves)
    if best is None:
        return [hull]
    return [
        hull for half in best[1] for hull in _split_where_hull_bulges(half, mesh, splits_left - 1)
    ]


def _write_obj_parts(path: Path, parts: list[trimesh.Trimesh | np.ndarray]) -> None:
    lines: list[str] = []
    offset = 1
    for index, part in enumerate(parts):
        hull = part if isinstance(part, trimesh.Trimesh) else trimesh.convex.convex_hull(part)
        lines.append(f"o part_{index}")
        lines.extend(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in hull.vertices)
        lines.extend(f"f {a + offset} {b + offset} {c + offset}" for a, b, c in hull.faces)
        offset += len(hull.vertices)
    path.write_text("\n".join(lines) + "\n")


def _quaternion_yaw(yaw_rad: float) -> list[float]:
    return Rotation.from_euler("z", yaw_rad).as_quat().tolist()


def _inertia(mesh: trimesh.Trimesh, mass_kg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre of mass, principal-axes orientation (quaternion xyzw) and principal moments
    (kg m^2) of a uniform solid ``mesh`` of ``mass_kg``; its bounding box stands in for a
    mesh that does not enclose a volume."""
    solid = mesh if mesh.is_volume else mesh.bounding_box
    solid = solid.copy()
    solid.density = mass_kg / solid.volume
    moments, axes = np.linalg.eigh(solid.moment_inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 0] = -axes[:, 0]
    return solid.center_mass, Rotation.from_matrix(axes).as_quat(), moments


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
            return pybullet.createCollisionShape(
                pybullet.GEOM_MESH,
                vertices=np.asarray(mesh.vertices).tolist(),
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
        ``friction`` is the lateral Coulomb coefficient. Mass properties are those of a
        uniform solid.
        """
        if mass_kg <= 0:
            raise InputError(f"object mass must be positive, got {mass_kg} kg")
        if len(mesh.faces) == 0:
            raise InputError("object mesh has no faces")
        collision = self._collision_shape(mesh)
        visual = pybullet.createVisualShape(
            pybullet.GEOM_MESH,
            vertices=np.asarray(mesh.vertices).tolist(),
            indices=np.asarray(mesh.faces).reshape(-1).tolist(),
            rgbaColor=rgba,
            physicsClientId=self.client,
        )
        center_mass, principal_axes, moments = _inertia(mesh, mass_kg)
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

    def step(self, steps: int = 1) -> None:
        """Advance the physics by ``steps`` time steps."""
        for _ in range(steps):
            pybullet.stepSimulation(physicsClientId=self.client)
