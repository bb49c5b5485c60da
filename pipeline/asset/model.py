"""The completed model of every stage as one asset: meshes, collision parts, mass and
symmetry, in the object frame of the selected stage (:mod:`.symmetry`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from pipeline.asset.collision import convex_parts
from pipeline.asset.mass import MassProperties, mass_properties
from pipeline.asset.meshing import View, half_widths, surface
from pipeline.asset.symmetry import SymmetryExport, export_symmetry, object_frame
from pipeline.metrics.fits import plane_after_bias
from pipeline.types import EstimateResult, StageEstimate


@dataclass(frozen=True)
class ModelAsset:
    """Everything a robot needs of the selected stage's model, and every stage's mesh.

    Attributes:
        T_robot_object: ``(4, 4)`` the object frame of the selected stage.
        selected_stage: the stage the model is made of.
        meshes: stage -> its watertight mesh, in the object frame of the selected stage.
        parts: the selected mesh's convex collision parts, object frame.
        mass: the selected mesh's mass properties, object frame.
        symmetry: the selected stage's plane with its covariance.
    """

    T_robot_object: np.ndarray
    selected_stage: int
    meshes: dict[int, trimesh.Trimesh]
    parts: tuple[trimesh.Trimesh, ...]
    mass: MassProperties
    symmetry: SymmetryExport

    @property
    def mesh(self) -> trimesh.Trimesh:
        return self.meshes[self.selected_stage]


def build_model(
    result: EstimateResult,
    density_kg_m3: float,
    mass_kg: float | None = None,
    table_z_m: float | None = None,
    viewpoint_m: np.ndarray | None = None,
) -> ModelAsset:
    """The asset of an estimate (frame R in, object frame out).

    Args:
        density_kg_m3, mass_kg: the solid's uniform density, or its mass when given.
        table_z_m: the table's height in frame R; None: the selected model's lowest point.
        viewpoint_m: the camera's optical centre in frame R (the cloud's
            ``viewpoint_m``), when known: regions the object hid from it are filled
            (:class:`~pipeline.asset.meshing.View`).

    Raises:
        ValueError: a stage's model has too few points above the table for a surface.
    """
    selected = result.selected
    table = float(selected.completed[:, 2].min()) if table_z_m is None else float(table_z_m)
    frames, solids = {}, {}
    for stage in result.stages:
        plane = plane_after_bias(stage.plane, stage.bias)
        frames[stage.stage] = object_frame(plane, stage.completed.mean(axis=0), table)
        origin, axes = frames[stage.stage][:3, 3], frames[stage.stage][:3, :3]
        local = (stage.completed - origin) @ axes
        solids[stage.stage] = half_widths(local, view=_view(stage, viewpoint_m, origin, axes))
    T_robot_object = frames[selected.stage]
    to_selected = np.linalg.inv(T_robot_object)
    meshes = {}
    for k, solid in solids.items():
        mesh = surface(solid)
        meshes[k] = mesh if k == selected.stage else mesh.apply_transform(to_selected @ frames[k])
    mass = mass_properties(meshes[selected.stage], density_kg_m3, mass_kg)
    symmetry = export_symmetry(
        selected.plane, selected.bias, selected.covariance, selected.completed.mean(axis=0), table
    )
    return ModelAsset(
        T_robot_object=T_robot_object,
        selected_stage=selected.stage,
        meshes=meshes,
        parts=tuple(convex_parts(solids[selected.stage], meshes[selected.stage].bounds)),
        mass=mass,
        symmetry=symmetry,
    )


def _view(
    stage: StageEstimate, viewpoint_m: np.ndarray | None, origin: np.ndarray, axes: np.ndarray
) -> View | None:
    """The camera's view of a stage's model in its object frame: the camera moved by the
    stage's bias like the points it saw, the completed model's first half
    (``{f_b(p_n)}``); None without a viewpoint."""
    if viewpoint_m is None or len(stage.completed) != 2 * len(stage.points):
        return None
    camera = stage.bias.apply(np.asarray(viewpoint_m, dtype=float).reshape(1, 3))[0]
    seen = stage.completed[: len(stage.points)]
    return View((camera - origin) @ axes, (seen - origin) @ axes)
