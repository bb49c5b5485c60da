"""Collision geometry of non-convex meshes: convex parts from PyBullet's V-HACD, shrink-wrapped
onto the surface and refined until no part sticks out of the mesh by more than
:data:`HULL_TOLERANCE_M`, cached on disk under ``$SYMFUSE_CACHE`` (default
``~/.cache/symfuse``) keyed by a hash of the mesh and the settings, so each shape is
decomposed once per machine. The parts are one OBJ file, one ``o`` object per part
(trimesh reads and writes it; PyBullet makes each object a convex child shape).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet
import trimesh

from pipeline.errors import ConfigError, InputError
from pipeline.metrics import MeshSurface, point_to_mesh_distances
from pipeline.sim import native_output_silenced

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


@contextlib.contextmanager
def _scratch_in(directory: Path) -> Iterator[Path]:
    """A temporary folder inside ``directory`` (created as needed), deleted afterwards.

    Raises:
        ConfigError: ``directory`` cannot be created or written: an environment problem,
            named by its variable (or the default folder and the variable that moves it).
    """
    try:
        directory.mkdir(parents=True, exist_ok=True)
        scratch = tempfile.TemporaryDirectory(dir=directory)
    except OSError as exc:
        where = (
            f"SYMFUSE_CACHE={os.environ['SYMFUSE_CACHE']}"
            if os.environ.get("SYMFUSE_CACHE")
            else f"the cache folder {cache_dir()}"
        )
        raise ConfigError(
            f"{where}: cannot keep the convex parts of the mesh in {directory} "
            f"({exc.strerror or exc}); set SYMFUSE_CACHE to a folder you can write"
        ) from None
    with scratch as folder:
        yield Path(folder)


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
    ``HULL_TOLERANCE_M``. A mesh that is not watertight (a scan with holes) has no inside
    to test against, so each part becomes the hull of the surface samples it holds
    (:func:`_surface_hulls`): its vertices lie on the surface, which removes the voxel's
    offset (2-4 mm on a scanned box), though not a bridge across a concavity.
    """
    directory = cache_dir() / "vhacd"
    fit = f"refined{HULL_TOLERANCE_M * 1e6:.0f}um" if mesh.is_watertight else "surface"
    key = f"{mesh_hash(mesh)[:32]}_r{resolution}_{fit}"
    path = directory / f"{key}.obj"
    if path.is_file():
        return path
    with _scratch_in(directory) as scratch:
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
        parts = read_convex_parts(result) if result.is_file() else []
        if not parts:
            raise InputError(f"convex decomposition of mesh {key} produced no parts")
        if mesh.is_watertight:
            parts = _faithful_hulls([_shrink_wrap(part, mesh) for part in parts], mesh)
        else:
            parts = _surface_hulls([trimesh.convex.convex_hull(part) for part in parts], mesh)
        staged = Path(scratch) / "wrapped.obj"
        write_convex_parts(staged, parts)
        os.replace(staged, path)
    return path


def read_convex_parts(path: Path) -> list[np.ndarray]:
    """Vertices ``(K, 3)`` of each ``o`` object in an OBJ file, in file order (faces are not
    needed: every part is convex and rebuilt as a hull)."""
    text = path.read_text()
    scene = trimesh.load(
        path,
        file_type="obj",
        force="scene",
        split_objects=True,
        group_material=False,
        process=False,
    )
    names = sorted(scene.geometry, key=lambda name: text.find(f"o {name}\n"))
    parts = [np.asarray(scene.geometry[name].vertices) for name in names]
    return [part for part in parts if len(part) >= 4]


def _shrink_wrap(vertices: np.ndarray, mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Convex hull of ``vertices`` after moving those outside ``mesh`` onto its surface."""
    outside = trimesh.proximity.signed_distance(mesh, vertices) < 0.0  # trimesh: outside < 0
    wrapped = vertices.copy()
    if outside.any():
        wrapped[outside] = trimesh.proximity.closest_point(mesh, vertices[outside])[0]
    return trimesh.convex.convex_hull(wrapped)


def _outside_distances(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """``(N,)`` how far (m) each point lies outside the watertight ``mesh`` (0 inside)."""
    surface = MeshSurface(mesh.vertices, mesh.faces)
    return np.where(surface.occupancy(points), 0.0, surface.distances(points))


def _faithful_hulls(hulls: list[trimesh.Trimesh], mesh: trimesh.Trimesh) -> list[trimesh.Trimesh]:
    """Convex parts covering the watertight ``mesh`` that stick out of it by at most
    ``HULL_TOLERANCE_M`` (as far as ``HULL_MAX_SPLITS`` halvings get).

    Dense surface samples are shared out among the parts (:func:`_shared_samples`), each
    part becomes the hull of its samples, and a hull that sticks out too far is cut in two
    (:func:`_split_where_hull_bulges`) and both halves refined.
    """
    points, owner = _shared_samples(hulls, mesh)
    refined: list[trimesh.Trimesh] = []
    for index in range(len(hulls)):
        refined.extend(_split_where_hull_bulges(points[owner == index], mesh, HULL_MAX_SPLITS))
    return refined


def _surface_hulls(hulls: list[trimesh.Trimesh], mesh: trimesh.Trimesh) -> list[trimesh.Trimesh]:
    """Each part of a mesh without an inside replaced by the hull of the surface samples it
    holds (:func:`_shared_samples`). A small part whose samples span no volume (a patch of
    one flat face) becomes the hull of its vertices moved to their closest surface points;
    when even those are flat it is a sliver along a face that holds nothing up, and is left
    out, as :func:`_split_where_hull_bulges` leaves out such slivers of a watertight mesh."""
    points, owner = _shared_samples(hulls, mesh)
    wrapped = []
    for index, hull in enumerate(hulls):
        on_surface = _solid_hull(points[owner == index])
        if on_surface is None:
            on_surface = _solid_hull(trimesh.proximity.closest_point(mesh, hull.vertices)[0])
        if on_surface is not None:
            wrapped.append(on_surface)
    return wrapped or hulls


def _solid_hull(points: np.ndarray) -> trimesh.Trimesh | None:
    """The convex hull of ``points``, None when they span no volume."""
    if len(points) < 4 or np.linalg.matrix_rank(points - points[0], tol=1e-9) < 3:
        return None
    hull = trimesh.convex.convex_hull(points)
    return hull if hull.volume > 1e-12 else None


def _shared_samples(
    hulls: list[trimesh.Trimesh], mesh: trimesh.Trimesh
) -> tuple[np.ndarray, np.ndarray]:
    """Dense samples of ``mesh``'s surface (and its vertices), ``(P, 3)``, and the index of
    the part each goes to: the hull it lies in, or the nearest."""
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
    return points, np.argmin(outside, axis=0)


def _hull_bulge(hull: trimesh.Trimesh, mesh: trimesh.Trimesh) -> tuple[float, np.ndarray]:
    """How far (m) ``hull`` sticks out of ``mesh`` at most, and where."""
    probes, _ = trimesh.sample.sample_surface(hull, 4000, seed=np.random.default_rng(0))
    probes = np.concatenate([probes, hull.vertices])
    outside = _outside_distances(probes, mesh)
    worst = int(np.argmax(outside))
    return float(outside[worst]), probes[worst]


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
    hull = _solid_hull(points)
    if hull is None:  # a sliver of coplanar samples holds nothing up
        return []
    bulge, worst = _hull_bulge(hull, mesh)
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
        worst_half = max(_hull_bulge(trimesh.convex.convex_hull(h), mesh)[0] for h in halves)
        if best is None or worst_half < best[0]:
            best = (worst_half, halves)
    if best is None:
        return [hull]
    return [
        hull for half in best[1] for hull in _split_where_hull_bulges(half, mesh, splits_left - 1)
    ]


def write_convex_parts(path: Path, parts: list[trimesh.Trimesh | np.ndarray]) -> None:
    """Write each part's convex hull as one ``o part_<i>`` object of an OBJ file (PyBullet
    makes each object one convex child of the collision shape)."""
    scene = trimesh.Scene()
    for index, part in enumerate(parts):
        hull = part if isinstance(part, trimesh.Trimesh) else trimesh.convex.convex_hull(part)
        scene.add_geometry(hull, geom_name=f"part_{index}")
    path.write_text(
        trimesh.exchange.obj.export_obj(
            scene, include_normals=False, include_color=False, include_texture=False, digits=9
        )
    )
