"""The object catalogue: the paper's objects as watertight meshes, and user meshes from files.

Catalogue objects are specified in ``objects/catalogue.toml`` (dimensions, mass, friction,
symmetry, description, paper reference) and generated procedurally with trimesh, so they
need no binary assets and every mesh is deterministic. Generated meshes are cached in memory;
:func:`load_object` hands out copies.

Object frame of every mesh :func:`load_object` returns: metres, z up, the base on ``z = 0``
and the axis-aligned bounding box centred on ``x = y = 0`` (user meshes are moved there unless
``recentre=False``). Catalogue box-like objects have their thickness along x; objects with a
single mirror plane point their asymmetric feature along +x and mirror about ``y = 0``.

The generators of each ``kind`` and their ``dimensions_m`` keys are in
:mod:`pipeline.catalogue.shapes`.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import tomllib
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from objects import ROOT as OBJECTS_ROOT
from pipeline.catalogue.shapes import GENERATORS
from pipeline.errors import ConfigError, InputError
from pipeline.io.units import MILLIMETRES_HINT, check_extent, check_not_metres, scale_of
from pipeline.symmetry import truth_file
from pipeline.types import Symmetry, SymmetryPlane

if TYPE_CHECKING:
    import trimesh

    from pipeline.catalogue.rest import RestPose

_log = logging.getLogger(__name__)

#: The catalogue specification file.
CATALOGUE_PATH = OBJECTS_ROOT / "catalogue.toml"
#: Mesh file formats :func:`load_object` reads (lower-case suffixes).
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".off", ".glb", ".gltf")
#: Mass given to a mesh loaded from a file (kg).
DEFAULT_MASS_KG = 0.3
#: Friction coefficient given to a mesh loaded from a file (-).
DEFAULT_FRICTION = 0.6

SymmetryClass = Literal["planar", "rotational", "none"]
_SYMMETRIES = ("planar", "rotational", "none")


@dataclass(frozen=True)
class CatalogueObjectInfo:
    """What the catalogue says about an object, without generating its mesh.

    Attributes:
        name: catalogue name (``cd_drive``, ``cup``, ...).
        kind: generator kind (``box``, ``cylinder``, ``jar``, ``mug``, ``loaf``, ``car``,
            ``spray_bottle``).
        description: one line.
        reference: where the paper uses the object.
        paper_set: ``"parallel-jaw"`` or ``"three-finger"``.
        mass_kg: mass (kg).
        friction: Coulomb friction coefficient (-).
        symmetry: ``"planar"``, ``"rotational"`` or ``"none"``.
        symmetry_plane: ground-truth mirror plane in the object frame (planar objects), else
            None; rotational objects are symmetric about every vertical plane through z.
        dimensions_m: the generator's dimensions (m).
    """

    name: str
    kind: str
    description: str
    reference: str
    paper_set: str
    mass_kg: float
    friction: float
    symmetry: SymmetryClass
    symmetry_plane: SymmetryPlane | None
    dimensions_m: Mapping[str, float]


@dataclass(frozen=True)
class CatalogueObject:
    """An object ready to be placed in a scene: its mesh and physical properties.

    Attributes:
        name: catalogue name, or the file's stem for a mesh loaded from a file.
        mesh: the surface in the object frame (metres; base on z = 0; centred in x, y).
        mass_kg: mass (kg).
        friction: Coulomb friction coefficient (-).
        symmetry: ``"planar"``, ``"rotational"`` or ``"none"`` (``"none"`` for files unless
            given their plane).
        symmetry_plane: ground-truth mirror plane in the object frame when planar, else None.
        dimensions_m: catalogue dimensions (m); for files the bounding-box extents
            ``extent_x``, ``extent_y``, ``extent_z``.
        description: one line.
        kind: generator kind, or ``"mesh"`` for a file.
        watertight: whether ``mesh`` is closed (always True for catalogue objects; scans
            may not be, and are accepted anyway).
        source: ``"catalogue"`` or the mesh file's path.
        urdf_path: for an object given as a URDF, the file: the simulator loads the body
            (collision shapes, inertia) from it, and ``mesh`` is its visual geometry in the
            URDF's base frame.
        symmetries: the true mirror planes and rotation axes in the object frame that its
            source states (``--symmetry``, a ``symmetry.json`` beside the mesh file:
            :mod:`pipeline.symmetry.truth_file`); empty: the evaluation finds them by
            search (:func:`pipeline.symmetry.truth_file.true_symmetries`).
        rest: the stable pose the object was turned into from its loaded frame
            (:mod:`pipeline.catalogue.rest`), or None: as loaded, upright.
    """

    name: str
    mesh: trimesh.Trimesh
    mass_kg: float
    friction: float
    symmetry: SymmetryClass
    symmetry_plane: SymmetryPlane | None
    dimensions_m: dict[str, float]
    description: str
    kind: str = "mesh"
    watertight: bool = True
    source: str = "catalogue"
    urdf_path: str | None = None
    symmetries: tuple[Symmetry, ...] = ()
    rest: RestPose | None = None


# ---------------------------------------------------------------- specification


@functools.cache
def _specification() -> dict[str, CatalogueObjectInfo]:
    try:
        with CATALOGUE_PATH.open("rb") as handle:
            tables = tomllib.load(handle)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{CATALOGUE_PATH}: cannot read the object catalogue ({exc})") from exc
    return {name: _parse_entry(name, table) for name, table in tables.items()}


def _parse_entry(name: str, table: Mapping[str, Any]) -> CatalogueObjectInfo:
    where = f"{CATALOGUE_PATH} [{name}]"

    def require(key: str) -> Any:
        if key not in table:
            raise ConfigError(f"{where}: missing key '{key}'")
        return table[key]

    kind = str(require("kind"))
    if kind not in GENERATORS:
        raise ConfigError(f"{where}: unknown kind '{kind}' (known: {', '.join(GENERATORS)})")
    symmetry = str(require("symmetry"))
    if symmetry not in _SYMMETRIES:
        raise ConfigError(f"{where}: symmetry must be one of {', '.join(_SYMMETRIES)}")
    plane = None
    if symmetry == "planar":
        plane_table = require("symmetry_plane")
        plane = SymmetryPlane.from_normal(plane_table["normal_xy"], plane_table["offset_m"])
    dimensions = {key: float(value) for key, value in require("dimensions_m").items()}
    return CatalogueObjectInfo(
        name=name,
        kind=kind,
        description=str(require("description")),
        reference=str(require("reference")),
        paper_set=str(require("paper_set")),
        mass_kg=float(require("mass_kg")),
        friction=float(require("friction")),
        symmetry=symmetry,  # type: ignore[arg-type]
        symmetry_plane=plane,
        dimensions_m=dimensions,
    )


def list_objects() -> list[CatalogueObjectInfo]:
    """Every catalogue object, in the order of ``objects/catalogue.toml``."""
    return list(_specification().values())


# ---------------------------------------------------------------- loading


def load_object(
    name_or_path: str | os.PathLike[str],
    *,
    recentre: bool = True,
    units: str = "m",
    symmetry: Sequence[float] = (),
) -> CatalogueObject:
    """A catalogue object by name, or a mesh file (OBJ, STL, PLY, ...) or URDF by path.

    Args:
        name_or_path: a catalogue name (see :func:`list_objects`) or a mesh file.
        recentre: for files, move the mesh so its base is on z = 0 and its bounding box is
            centred on x = y = 0 (catalogue meshes always are).
        units: the length unit of a mesh file (``m`` or ``mm``; it is converted to metres).
            A URDF states its own scale in its ``<mesh scale=...>`` elements.
        symmetry: a mesh file's true vertical mirror plane ``(NX, NY, D)``, the points with
            ``NX x + NY y = D`` in the file's frame and ``units`` (``trial.symmetry``), or
            empty: the object is then ``planar`` about it (moved with the recentring).

    Raises:
        InputError: unknown name (the message lists the catalogue); a missing, unreadable
            or empty mesh file, non-finite vertices, or a size that says millimetres (the
            message names the path).
    """
    text = os.fspath(name_or_path)
    catalogue = _specification()
    is_mesh = text not in catalogue and Path(text).suffix.lower() != ".urdf"
    if symmetry and not is_mesh:
        raise InputError(
            f"'{text}' states its own symmetry; --symmetry (trial.symmetry) applies to mesh files"
        )
    if text in catalogue:
        if units != "m":
            raise InputError(
                f"'{text}' is a catalogue object (in metres); --units applies to mesh files"
            )
        info = catalogue[text]
        return CatalogueObject(
            name=info.name,
            mesh=_generated_mesh(info.name).copy(),
            mass_kg=info.mass_kg,
            friction=info.friction,
            symmetry=info.symmetry,
            symmetry_plane=info.symmetry_plane,
            dimensions_m=dict(info.dimensions_m),
            description=info.description,
            kind=info.kind,
            watertight=True,
            source="catalogue",
        )
    path = Path(text)
    if path.suffix.lower() == ".urdf":
        if units != "m":
            raise InputError(
                f"{path}: a URDF gives its meshes' scale itself (<mesh scale=...>); "
                "--units applies to mesh files"
            )
        return _load_urdf(path)
    if path.suffix.lower() in MESH_SUFFIXES or path.exists() or os.sep in text:
        return _load_mesh_file(path, recentre=recentre, units=units, symmetry=symmetry)
    raise InputError(f"unknown object '{text}'; catalogue objects: {', '.join(catalogue)}")


def _checked_mesh(
    mesh: Any, path: Path, what: str, hint: str = MILLIMETRES_HINT
) -> trimesh.Trimesh:
    """``mesh`` if it has triangles, finite vertices, a volume and a graspable size."""
    import trimesh

    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(f"{path}: {what}")
    if not np.isfinite(mesh.vertices).all():
        raise InputError(f"{path}: the mesh has NaN or infinite vertices")
    check_extent(mesh.extents, str(path), hint)
    # The spread of the vertices along their thinnest direction, against their widest: a
    # flat mesh has no inside to grasp, and the simulator's convex decomposition of one
    # never ends.
    spread = np.linalg.svd(mesh.vertices - mesh.vertices.mean(axis=0), compute_uv=False)
    if spread[-1] <= FLAT_RATIO * spread[0]:
        raise InputError(f"{path}: the mesh is flat (all its vertices lie in one plane): no solid")
    return mesh


#: Below this ratio of the vertices' spread along their thinnest direction to their widest
#: a mesh is flat: the float rounding of a plane's points, not a thickness.
FLAT_RATIO = 1e-9


def _user_plane(symmetry: Sequence[float], scale: float, shift_xy: np.ndarray) -> SymmetryPlane:
    """The plane ``(NX, NY, D)`` of a mesh file (``D`` in its units, ``scale`` metres per
    unit) in the object frame, the mesh having moved by ``shift_xy`` (m) when placed.

    Raises:
        InputError: not three numbers, or a zero normal.
    """
    if len(symmetry) != 3 or not (symmetry[0] or symmetry[1]):
        raise InputError(
            f"--symmetry (trial.symmetry) {list(symmetry)}: expected NX, NY, D with a "
            "non-zero normal (NX, NY)"
        )
    plane = SymmetryPlane.from_normal(np.array(symmetry[:2]), scale * symmetry[2])
    return SymmetryPlane(plane.theta_rad, plane.offset_m + float(plane.normal[:2] @ shift_xy))


def _load_mesh_file(
    path: Path, *, recentre: bool, units: str = "m", symmetry: Sequence[float] = ()
) -> CatalogueObject:
    if not path.is_file():
        what = "a folder, not a mesh file" if path.is_dir() else "no such mesh file"
        raise InputError(f"{path}: {what}")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(f"{path}: unsupported mesh format (use {', '.join(MESH_SUFFIXES)})")
    import trimesh

    try:
        with warnings.catch_warnings():
            # A scan's OBJ may carry NaN normals (the YCB mug's do): trimesh's vertex merge
            # then warns while casting them, though the vertices are finite (checked below).
            warnings.simplefilter("ignore", RuntimeWarning)
            mesh = trimesh.load(path, force="mesh")
            # trimesh drops a NaN vertex, and the faces that use it, without a word: the
            # file as written must be finite, not just what is left of it.
            raw = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        detail = (str(exc).splitlines() or [""])[0]
        raise InputError(f"{path}: cannot read mesh ({type(exc).__name__}: {detail})") from exc
    if isinstance(raw, trimesh.Trimesh) and not np.isfinite(raw.vertices).all():
        row = int(np.flatnonzero(~np.isfinite(raw.vertices).all(axis=1))[0])
        raise InputError(f"{path}: vertex {row + 1} has NaN or infinite coordinates")
    scale = scale_of(units, str(path))
    if isinstance(mesh, trimesh.Trimesh) and scale != 1.0:
        mesh.apply_scale(scale)
    mesh = _checked_mesh(mesh, path, "contains no triangles")
    check_not_metres(mesh.extents, units, str(path))
    lower = mesh.bounds[0]
    if recentre:
        mesh = place_on_table(mesh)
    shift = mesh.bounds[0] - lower
    plane = _user_plane(symmetry, scale, shift[:2]) if symmetry else None
    symmetries: tuple[Symmetry, ...] = ()
    if plane is not None:
        symmetries = (Symmetry.from_plane(plane),)
    elif (stated := truth_file.beside(path)) is not None:
        symmetries = tuple(_moved(s, shift) for s in truth_file.read_symmetries(stated)[0])
        level = [found for found in map(vertical_plane, symmetries) if found is not None]
        plane = level[0] if level else None
    watertight = bool(mesh.is_watertight)
    if not watertight:
        _log.warning("%s: mesh is not watertight; accepted, volumes and inside tests are off", path)
    extents = mesh.extents
    return CatalogueObject(
        name=path.stem,
        mesh=mesh,
        mass_kg=DEFAULT_MASS_KG,
        friction=DEFAULT_FRICTION,
        symmetry="none" if plane is None else "planar",
        symmetry_plane=plane,
        dimensions_m={f"extent_{axis}": float(v) for axis, v in zip("xyz", extents, strict=True)},
        description=f"mesh loaded from {path}",
        kind="mesh",
        watertight=watertight,
        source=str(path),
        symmetries=symmetries,
    )


def _moved(symmetry: Symmetry, shift_m: np.ndarray) -> Symmetry:
    """A symmetry of a mesh file's frame in the object frame, the mesh moved by ``shift_m``."""
    return Symmetry(
        symmetry.kind, symmetry.direction, symmetry.point_m + shift_m, None, symmetry.residual_m
    )


def vertical_plane(symmetry: Symmetry) -> SymmetryPlane | None:
    """The symmetry as the paper's vertical plane, when it is a plane with a level normal:
    the plane errors of the evaluation
    (:func:`pipeline.metrics.evaluation.plane_errors`) score it."""
    normal = symmetry.direction
    if not symmetry.is_plane or abs(normal[2]) > 1e-6:
        return None
    return SymmetryPlane.from_normal(normal[:2], float(normal @ symmetry.point_m))


def _load_urdf(path: Path) -> CatalogueObject:
    """A single-body object described by a URDF: its visual meshes, in the base link frame,
    are the ground truth; the simulator loads the URDF itself for the physics."""
    import yourdfpy

    if not path.is_file():
        raise InputError(f"{path}: no such URDF file")
    with _logged("yourdfpy") as said:  # it logs what it could not read, then goes on
        try:
            urdf = yourdfpy.URDF.load(str(path), load_meshes=True)
            mesh = urdf.scene.to_geometry()
        except Exception as exc:  # yourdfpy/lxml/trimesh raise many types for malformed files
            detail = (said or str(exc).splitlines() or [""])[0]
            raise InputError(f"{path}: cannot read URDF ({type(exc).__name__}: {detail})") from exc
    no_mesh = f"the URDF has no visual mesh ({said[-1]})" if said else "the URDF has no visual mesh"
    mesh = _checked_mesh(
        mesh,
        path,
        no_mesh,
        hint='looks like millimetres: give its meshes scale="0.001 0.001 0.001"',
    )
    inertial = urdf.link_map[urdf.base_link].inertial
    mass = inertial.mass if inertial is not None and inertial.mass else DEFAULT_MASS_KG
    return CatalogueObject(
        name=urdf.robot.name or path.stem,
        mesh=mesh,
        mass_kg=float(mass),
        friction=DEFAULT_FRICTION,
        symmetry="none",
        symmetry_plane=None,
        dimensions_m={
            f"extent_{axis}": float(v) for axis, v in zip("xyz", mesh.extents, strict=True)
        },
        description=f"URDF body loaded from {path}",
        kind="urdf",
        watertight=bool(mesh.is_watertight),
        source=str(path),
        urdf_path=str(path),
    )


@functools.cache
def _generated_mesh(name: str) -> trimesh.Trimesh:
    info = _specification()[name]
    try:
        mesh = GENERATORS[info.kind](info.dimensions_m)
    except KeyError as exc:
        raise ConfigError(
            f"{CATALOGUE_PATH} [{name}]: dimensions_m lacks {exc} for kind '{info.kind}'"
        ) from exc
    return place_on_table(mesh)


def place_on_table(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """A copy of ``mesh`` translated so its base is on z = 0 and its bounding box is centred
    on x = y = 0."""
    lower, upper = mesh.bounds
    offset = -np.array([(lower[0] + upper[0]) / 2.0, (lower[1] + upper[1]) / 2.0, lower[2]])
    placed = mesh.copy()
    placed.apply_translation(offset)
    return placed


@contextlib.contextmanager
def _logged(name: str) -> Iterator[list[str]]:
    """Collect what the logger ``name`` says (its records' messages, in order) instead of
    printing it: a library's own lines must not come before the one-line error."""
    said: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            said.append(record.getMessage())

    logger = logging.getLogger(name)
    handler, propagate = Collect(), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield said
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate
