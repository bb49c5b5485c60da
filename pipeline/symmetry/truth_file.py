"""``symmetry.json``: an object's true symmetries stored beside its mesh file.

A mesh file ``DIR/NAME.obj`` (any format :func:`pipeline.catalogue.objects.load_object` reads) has
its true mirror planes and rotation axes in ``DIR/symmetry.json`` when that file exists and
names it::

    {
      "mesh": "NAME.obj",
      "units": "m",
      "symmetries": [
        {"kind": "plane", "normal": [1, 0, 0], "point": [0.01, 0, 0]},
        {"kind": "axis", "direction": [0, 0, 1], "point": [0.01, 0.02, 0]}
      ]
    }

Coordinates are in the mesh file's own frame and in ``units`` (``m`` or ``mm``), as the file
stores its vertices; ``symfuse symmetry MESH`` writes such a file from the search
(:mod:`pipeline.symmetry.search`). A ``symmetry.json`` naming another mesh of the folder
does not apply.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.errors import InputError
from pipeline.io.formats import check_keys, read_json
from pipeline.io.units import scale_of
from pipeline.types import Symmetry

if TYPE_CHECKING:
    from pipeline.catalogue.objects import CatalogueObject

_log = logging.getLogger(__name__)

#: The file's name, beside the mesh.
FILE_NAME = "symmetry.json"
_KEYS = ("mesh", "units", "symmetries", "search")
_ENTRY_KEYS = {
    "plane": ("kind", "normal", "point", "residual"),
    "axis": ("kind", "direction", "point", "residual"),
}


def beside(mesh_path: Path) -> Path | None:
    """The ``symmetry.json`` beside ``mesh_path`` when it exists and names that mesh."""
    path = Path(mesh_path).parent / FILE_NAME
    if not path.is_file():
        return None
    document = read_json(path)
    if not isinstance(document, dict) or not isinstance(document.get("mesh"), str):
        raise InputError(f"{path}: expected an object with a 'mesh' naming the mesh file")
    return path if document["mesh"] == Path(mesh_path).name else None


def read_symmetries(path: Path) -> tuple[Sequence[Symmetry], float]:
    """The symmetries of a ``symmetry.json`` in its mesh file's frame, converted to metres,
    and the scale of its units (m per unit).

    Raises:
        InputError: unreadable JSON, an unknown key, a missing or malformed entry (the
            message names the file and the entry).
    """
    document = read_json(path)
    if not isinstance(document, dict):
        raise InputError(f"{path}: expected a JSON object")
    check_keys(document, _KEYS, "", path)
    scale = scale_of(str(document.get("units", "m")), str(path))
    entries = document.get("symmetries")
    if not isinstance(entries, list):
        raise InputError(f"{path}: 'symmetries' must be a list of planes and axes")
    return tuple(
        _entry(entry, f"symmetries[{k}]", path, scale) for k, entry in enumerate(entries)
    ), scale


def _entry(entry: Any, where: str, path: Path, scale: float) -> Symmetry:
    kind = entry.get("kind") if isinstance(entry, dict) else None
    if kind not in _ENTRY_KEYS:
        raise InputError(f"{path}: {where}.kind must be 'plane' or 'axis'")
    check_keys(entry, _ENTRY_KEYS[kind], f"{where}.", path)
    key = "normal" if kind == "plane" else "direction"
    vectors = []
    for name in (key, "point"):
        value = np.asarray(entry.get(name, ()), dtype=object)
        try:
            vector = value.astype(np.float64)
        except (TypeError, ValueError):
            vector = np.zeros(0)
        if vector.shape != (3,) or not np.isfinite(vector).all():
            raise InputError(f"{path}: {where}.{name} must be three finite numbers")
        vectors.append(vector)
    if not np.linalg.norm(vectors[0]) > 0.0:
        raise InputError(f"{path}: {where}.{key} must not be zero")
    residual = float(entry.get("residual", np.nan)) * scale
    return Symmetry(kind, vectors[0], vectors[1] * scale, None, residual)


def symmetries_to_json(
    symmetries: Sequence[Symmetry], mesh_name: str, search: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The ``symmetry.json`` document of symmetries in a mesh's frame, metres."""
    entries = []
    for symmetry in symmetries:
        entry: dict[str, Any] = {"kind": "plane" if symmetry.is_plane else "axis"}
        entry["normal" if symmetry.is_plane else "direction"] = [
            float(v) for v in symmetry.direction
        ]
        entry["point"] = [float(v) for v in symmetry.point_m]
        if np.isfinite(symmetry.residual_m):
            entry["residual"] = float(symmetry.residual_m)
        entries.append(entry)
    document: dict[str, Any] = {"mesh": mesh_name, "units": "m", "symmetries": entries}
    if search is not None:
        document["search"] = search
    return document


def true_symmetries(obj: CatalogueObject) -> tuple[Symmetry, ...]:
    """An object's true symmetries in its object frame: those its source states, else the
    search's on its mesh."""
    if obj.symmetries:
        return obj.symmetries
    return searched_symmetries(np.asarray(obj.mesh.vertices), np.asarray(obj.mesh.faces))


def searched_symmetries(vertices: np.ndarray, faces: np.ndarray) -> tuple[Symmetry, ...]:
    """The search's symmetries of a mesh (:func:`~pipeline.symmetry.search.mesh_symmetries`),
    kept as a ``symmetry.json`` in the cache folder (``$SYMFUSE_CACHE/symmetry``, default
    ``~/.cache/symfuse/symmetry``) under the digest of the mesh and the search's version: a
    mesh is searched once per machine. The catalogue's meshes are searched once for
    everyone: their results ship in ``objects/symmetry/`` under the same names (the search
    takes seconds per mesh, and every trial's evaluation asks for them)."""
    import trimesh

    from objects import ROOT as OBJECTS_ROOT
    from pipeline.sim.collision import cache_dir, mesh_hash
    from pipeline.symmetry.search import SEARCH_VERSION, mesh_symmetries

    digest = mesh_hash(trimesh.Trimesh(vertices, faces, process=False))
    name = f"{digest}-v{SEARCH_VERSION}.json"
    for path in (OBJECTS_ROOT / "symmetry" / name, cache_dir() / "symmetry" / name):
        if path.is_file():
            return tuple(read_symmetries(path)[0])
    path = cache_dir() / "symmetry" / name
    found = mesh_symmetries(vertices, faces)
    document = symmetries_to_json(found.symmetries, digest)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.part")
        partial.write_text(json.dumps(document, indent=2))
        partial.replace(path)
    except OSError as exc:
        _log.warning("%s: cannot keep the searched symmetries (%s)", path, exc.strerror or exc)
    return found.symmetries
