"""Volume, centre of mass and inertia of a closed mesh of uniform density."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh


@dataclass(frozen=True)
class MassProperties:
    """A solid of uniform density, in the frame of its mesh.

    Attributes:
        volume_m3: its volume.
        mass_kg: its mass.
        density_kg_m3: the density (given, or the given mass over the volume).
        centre_of_mass_m: ``(3,)`` its centre of mass.
        inertia_kg_m2: ``(3, 3)`` its inertia tensor about the centre of mass, along the
            mesh frame's axes.
    """

    volume_m3: float
    mass_kg: float
    density_kg_m3: float
    centre_of_mass_m: np.ndarray
    inertia_kg_m2: np.ndarray

    def to_json(self) -> dict:
        return {
            "volume_m3": self.volume_m3,
            "mass_kg": self.mass_kg,
            "density_kg_m3": self.density_kg_m3,
            "centre_of_mass_m": self.centre_of_mass_m.tolist(),
            "inertia_kg_m2": self.inertia_kg_m2.tolist(),
        }


def signed_volume(mesh: trimesh.Trimesh) -> float:
    """The volume a closed mesh bounds (m^3): positive when its faces are ordered
    counter-clockwise seen from outside, negative when they point inwards."""
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def is_closed(mesh: trimesh.Trimesh) -> bool:
    """Whether a mesh is closed and consistently oriented: every directed edge of its
    triangles appears exactly once and so does its reverse (so each edge joins exactly two
    triangles that run along it in opposite directions)."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if len(faces) == 0:
        return False
    start = faces.ravel()
    end = faces[:, [1, 2, 0]].ravel()
    count = int(faces.max()) + 1
    # Sorted, the directed edges must hold no value twice and equal their reverses, sorted
    # (a sort each: ``np.unique`` costs several times as much on a model's mesh).
    edges = np.sort(start * count + end)
    if np.any(edges[1:] == edges[:-1]):
        return False
    return bool(np.array_equal(edges, np.sort(end * count + start)))


def mass_properties(
    mesh: trimesh.Trimesh, density_kg_m3: float, mass_kg: float | None = None
) -> MassProperties:
    """The mass properties of the solid a closed, outward-oriented mesh bounds (trimesh's
    exact integration over the triangles), of density ``density_kg_m3`` or, when
    ``mass_kg`` is given, of the density that gives that mass.

    Raises:
        ValueError: the mesh is not watertight or bounds no positive volume.
    """
    if not is_closed(mesh):
        raise ValueError("mass properties need a watertight mesh")
    unit = trimesh.triangles.mass_properties(mesh.triangles, density=1.0, skip_inertia=False)
    volume = float(unit.volume)
    if not volume > 0.0:
        raise ValueError(f"the mesh bounds no positive volume ({volume:g} m^3)")
    density = float(mass_kg) / volume if mass_kg is not None else float(density_kg_m3)
    return MassProperties(
        volume_m3=volume,
        mass_kg=density * volume,
        density_kg_m3=density,
        centre_of_mass_m=np.asarray(unit.center_mass, dtype=float),
        inertia_kg_m2=density * np.asarray(unit.inertia, dtype=float),
    )
