"""Geometry the recording draws that no run file holds: the symmetry plane as a quad over
the model, and the hand's link meshes at the grasp (frame R, metres)."""

from __future__ import annotations

import numpy as np

from ..types import SymmetryPlane

#: The plane quad reaches this far beyond the model on each side (m).
PLANE_MARGIN_M = 0.015


def plane_quad(plane: SymmetryPlane, points: np.ndarray) -> np.ndarray:
    """``(4, 3)`` corners of the part of a vertical plane that spans ``points``: along the
    plane as far as the points reach plus :data:`PLANE_MARGIN_M`, from their lowest to their
    highest point, centred on their centroid's projection."""
    normal = plane.normal
    along = np.array([-normal[1], normal[0], 0.0])
    centre = points.mean(axis=0)
    centre = centre - (centre @ normal - plane.offset_m) * normal
    reach = np.abs((points - centre) @ along).max() + PLANE_MARGIN_M
    low, high = points[:, 2].min(), points[:, 2].max()
    corners = []
    for side, z in ((-1, low), (1, low), (1, high), (-1, high)):
        corner = centre + side * reach * along
        corners.append([corner[0], corner[1], z])
    return np.array(corners)


def hand_link_meshes(
    gripper: str, joint_positions: dict[str, float] | None, T_robot_hand: np.ndarray, plan
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``link -> (vertices, faces, normals)`` of a shipped hand in frame R.

    The joints are at ``joint_positions`` (after the grasp closed) or, when the run did not
    record them, at the plan's opening. Each face gets its own vertices, so the boxes and
    cylinders of the URDF shade flat.
    """
    import trimesh
    import yourdfpy

    from robots import ROOT

    from ..sim.hands import HAND_MODELS

    model = HAND_MODELS.get(gripper)
    if model is None:
        return {}
    urdf = yourdfpy.URDF.load(str(ROOT / model.urdf))
    if joint_positions is None:
        joint_positions = model.open_configuration(plan.opening_m, plan.spread_rad)
    urdf.update_cfg({k: v for k, v in joint_positions.items() if k in urdf.actuated_joint_names})
    scene = urdf.scene
    shapes: dict[str, list[trimesh.Trimesh]] = {}
    for node in scene.graph.nodes_geometry:
        T_hand_shape, geometry = scene.graph[node]
        link = scene.graph.transforms.parents[node]
        shape = trimesh.Trimesh(scene.geometry[geometry].vertices, scene.geometry[geometry].faces)
        shapes.setdefault(link, []).append(shape.apply_transform(T_robot_hand @ T_hand_shape))
    meshes = {}
    for link, parts in shapes.items():
        mesh = trimesh.util.concatenate(parts)
        mesh.unmerge_vertices()
        meshes[link] = (np.asarray(mesh.vertices), np.asarray(mesh.faces), mesh.vertex_normals)
    return meshes
