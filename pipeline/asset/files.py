"""The files of the completed model a run writes: ``model.obj``, ``model_stage{k}.obj``,
``model_collision.obj`` and ``model.urdf`` (``docs/formats.md``, "A trial's folder")."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from pipeline.asset.mass import is_closed, signed_volume
from pipeline.asset.meshing import OBJ_DECIMALS
from pipeline.asset.model import ModelAsset, build_model
from pipeline.asset.urdf import urdf_text
from pipeline.config import ModelSettings
from pipeline.types import EstimateResult

MODEL_FILE = "model.obj"
COLLISION_FILE = "model_collision.obj"
URDF_FILE = "model.urdf"


def stage_file(stage: int) -> str:
    return f"model_stage{stage}.obj"


def obj_text(objects: Sequence[tuple[str, trimesh.Trimesh]]) -> str:
    """Wavefront OBJ of named meshes, each its own ``o`` object (vertices in metres)."""
    lines, offset = [], 1
    for name, mesh in objects:
        vertices = np.asarray(mesh.vertices, dtype=float)
        faces = np.asarray(mesh.faces, dtype=np.int64) + offset
        lines.append(f"o {name}\n")
        # Formatting Python floats is three times faster than numpy's.
        lines.append(
            (f"v %.{OBJ_DECIMALS}f %.{OBJ_DECIMALS}f %.{OBJ_DECIMALS}f\n" * len(vertices))
            % tuple(vertices.ravel().tolist())
        )
        lines.append(("f %d %d %d\n" * len(faces)) % tuple(faces.ravel().tolist()))
        offset += len(vertices)
    return "".join(lines)


def write_model(
    out_dir: Path,
    result: EstimateResult,
    settings: ModelSettings,
    table_z_m: float | None,
    viewpoint_m: np.ndarray | None = None,
    name: str = "model",
) -> tuple[ModelAsset | None, dict[str, Any]]:
    """Build the asset of ``result`` (:func:`~pipeline.asset.model.build_model`), write its
    files into ``out_dir`` and return it with ``result.json``'s ``model`` entry.

    Args:
        settings: the config's ``[model]`` (density, or mass when above 0).
        table_z_m: the table's height in frame R; None: the model's lowest point.
        viewpoint_m: the camera's optical centre in frame R, when known.

    A model too small for a surface writes nothing: the entry says why, and the asset is
    None."""
    mass = settings.mass_kg if settings.mass_kg > 0.0 else None
    try:
        asset = build_model(result, settings.density_kg_m3, mass, table_z_m, viewpoint_m)
    except ValueError as exc:
        return None, {"status": "failed", "reason": str(exc)}
    out_dir = Path(out_dir)
    for stage, mesh in asset.meshes.items():
        text = obj_text([(name, mesh)])
        (out_dir / stage_file(stage)).write_text(text)
        if stage == asset.selected_stage:
            (out_dir / MODEL_FILE).write_text(text)
    parts = [(f"convex_{k}", part) for k, part in enumerate(asset.parts)]
    (out_dir / COLLISION_FILE).write_text(obj_text(parts))
    (out_dir / URDF_FILE).write_text(urdf_text(name, asset.mass, MODEL_FILE, COLLISION_FILE))
    return asset, model_to_json(asset)


def model_to_json(asset: ModelAsset) -> dict[str, Any]:
    """``result.json``'s ``model``: the files, the object frame, the selected mesh's mass
    properties (object frame; the centre of mass in frame R too) and the symmetry."""
    centre = asset.T_robot_object @ np.append(asset.mass.centre_of_mass_m, 1.0)
    return {
        "status": "ok",
        "selected_stage": asset.selected_stage,
        "files": {
            "mesh": MODEL_FILE,
            "stages": {str(k): stage_file(k) for k in asset.meshes},
            "collision": COLLISION_FILE,
            "urdf": URDF_FILE,
        },
        "frame": "object",
        "T_robot_object": asset.T_robot_object.tolist(),
        "watertight": {str(k): is_closed(mesh) for k, mesh in asset.meshes.items()},
        "stage_volumes_m3": {str(k): signed_volume(mesh) for k, mesh in asset.meshes.items()},
        "collision_parts": len(asset.parts),
        **asset.mass.to_json(),
        "centre_of_mass_robot_m": centre[:3].tolist(),
        "symmetry": asset.symmetry.to_json(),
    }
