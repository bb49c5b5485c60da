"""Exact point-to-mesh distances against brute force by another route and against open3d's
``RaycastingScene``; axis-line crossings through shared edges and corners."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pipeline.metrics import MeshSurface, mesh_occupancy
from pipeline.metrics.mesh_queries import _crossings, grid_crossings, ray_crossings


def _segment(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    along = b - a
    t = np.einsum("ij,ij->i", points - a, along) / np.einsum("ij,ij->i", along, along)
    return np.linalg.norm(points - (a + along * np.clip(t, 0.0, 1.0)[:, None]), axis=1)


def _by_projection(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Distance of point ``k`` to triangle ``k``: the foot of the perpendicular on the
    triangle's plane where it falls inside (barycentric coordinates from the normal
    equations), else the nearest of the three edges."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    edges = np.stack([b - a, c - a], axis=2)  # (N, 3, 2)
    gram = np.einsum("nki,nkj->nij", edges, edges)
    st = np.linalg.solve(gram, np.einsum("nki,nk->ni", edges, points - a)[..., None])[..., 0]
    foot = a + np.einsum("nki,ni->nk", edges, st)
    inside = (st[:, 0] >= 0.0) & (st[:, 1] >= 0.0) & (st.sum(axis=1) <= 1.0)
    rims = np.min([_segment(points, a, b), _segment(points, b, c), _segment(points, c, a)], axis=0)
    return np.where(inside, np.linalg.norm(points - foot, axis=1), rims)


def _brute_force(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """The least distance over every triangle, every pair by :func:`_by_projection`."""
    triangles = np.asarray(mesh.triangles)
    pairs = _by_projection(
        np.repeat(points, len(triangles), axis=0), np.tile(triangles, (len(points), 1, 1))
    )
    return pairs.reshape(len(points), len(triangles)).min(axis=1)


def _meshes() -> list[trimesh.Trimesh]:
    """Meshes whose triangles differ in size by orders of magnitude, tilted and moved off
    the origin."""
    rng = np.random.default_rng(3)
    box = trimesh.creation.box(extents=(0.17, 0.146, 0.042))  # twelve long triangles
    ring = trimesh.creation.annulus(r_min=0.02, r_max=0.04, height=0.05, sections=24)
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.01)
    ball.apply_translation([0.08, 0.0, 0.0])
    meshes = []
    for mesh in (box, ring, trimesh.util.concatenate([ring, ball])):
        turn = trimesh.transformations.random_rotation_matrix(rng.random(3))
        turn[:3, 3] = [0.6, -0.2, 0.1]
        meshes.append(mesh.copy().apply_transform(turn))
    return meshes


MESHES = _meshes()
IDS = ["box", "ring", "ring and ball"]


@pytest.mark.parametrize("mesh", MESHES, ids=IDS)
def test_mesh_distances_are_the_least_over_every_triangle(mesh):
    """Points near the surface, far from it and on its corners."""
    rng = np.random.default_rng(4)
    near = mesh.sample(300, seed=1) + rng.normal(0.0, 0.003, (300, 3))
    far = mesh.centroid + rng.uniform(-0.15, 0.15, (100, 3))
    points = np.concatenate([near, far, mesh.vertices[:30]])
    found = MeshSurface(mesh.vertices, mesh.faces).distances(points)
    np.testing.assert_allclose(found, _brute_force(points, mesh), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("mesh", MESHES, ids=IDS)
def test_mesh_distances_agree_with_open3d_to_its_float32_rounding(mesh):
    """open3d computes in float32 (after shifting the mesh to its bounding box's centre):
    its distances are ours to within a few units in the last place of the coordinates."""
    from pipeline.io.open3d_loader import open3d

    o3d = open3d()
    rng = np.random.default_rng(5)
    points = mesh.sample(5000, seed=2) + rng.normal(0.0, 0.005, (5000, 3))
    origin = mesh.bounds.mean(axis=0)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor((mesh.vertices - origin).astype(np.float32)),
        o3d.core.Tensor(mesh.faces.astype(np.uint32)),
    )
    theirs = scene.compute_distance(o3d.core.Tensor((points - origin).astype(np.float32)))
    ours = MeshSurface(mesh.vertices, mesh.faces).distances(points)
    np.testing.assert_allclose(ours, theirs.numpy(), rtol=0.0, atol=5e-8)


def _octahedron(scale: float) -> trimesh.Trimesh:
    corners = scale * np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float
    )
    return trimesh.convex.convex_hull(corners)


def test_lines_through_shared_corners_and_edges_cross_once_per_side():
    """Lines of a grid through an octahedron's corners and along its edges (each shared by
    two or four triangles) meet its surface exactly twice, or not at all outside it."""
    mesh = _octahedron(0.04)
    triangles = np.asarray(mesh.triangles)
    for axis in range(3):
        line, height = grid_crossings(triangles, axis, np.array([-0.04, -0.04]), 0.01, (9, 9))
        counts = np.bincount(line, minlength=81).reshape(9, 9)
        u, v = np.meshgrid(np.arange(9) - 4, np.arange(9) - 4, indexing="ij")
        np.testing.assert_array_equal(counts[np.abs(u) + np.abs(v) < 4], 2)
        assert np.all(counts[np.abs(u) + np.abs(v) > 4] == 0)
        assert np.all(counts % 2 == 0)  # the rim itself grazes: 0 or 2 there
        # Through the centre line the crossings are the two opposite corners.
        centre = line == 4 * 9 + 4
        np.testing.assert_allclose(np.sort(height[centre]), [-0.04, 0.04], atol=1e-15)


def _every_pair(triangles, axis, low, pitch, counts):
    """:func:`grid_crossings` by testing every triangle against every line of the grid."""
    i, j = (a.reshape(-1) for a in np.meshgrid(*map(np.arange, counts), indexing="ij"))
    owner = np.repeat(np.arange(len(triangles)), len(i))
    points = np.column_stack([low[0] + pitch * i, low[1] + pitch * j])
    pair, height = _crossings(triangles, owner, axis, np.tile(points, (len(triangles), 1)))
    return np.tile(i * counts[1] + j, len(triangles))[pair], height


@pytest.mark.parametrize("shape", ["cylinder", "sphere"])
def test_lines_found_per_row_are_those_of_every_pair(shape):
    """The lines each triangle is tested against (its span along each row) miss no
    crossing: the same crossings, in the same order, as every triangle against every line,
    with grid lines through the cylinder's cap centres, rims and corners."""
    if shape == "cylinder":  # fans whose long thin triangles cross the grid's diagonals
        mesh = trimesh.creation.cylinder(radius=0.03, height=0.04, sections=32)
    else:
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
        turn = trimesh.transformations.random_rotation_matrix(np.random.default_rng(4).random(3))
        mesh.apply_transform(turn)
    triangles = np.asarray(mesh.triangles)
    for axis in range(3):
        low, counts = np.array([-0.03, -0.03]), (25, 25)
        expected = _every_pair(triangles, axis, low, 0.0025, counts)
        found = grid_crossings(triangles, axis, low, 0.0025, counts)
        assert len(found[0]) > 100
        np.testing.assert_array_equal(found[0], expected[0])
        np.testing.assert_array_equal(found[1], expected[1])


def test_rays_from_points_count_crossings_ahead_of_them_only():
    mesh = _octahedron(0.04)
    starts = np.array([[0.0, 0.0, -0.1], [0.0, 0.0, 0.0], [0.0, 0.0, 0.05], [0.01, 0.0, 0.0]])
    ray, height = ray_crossings(np.asarray(mesh.triangles), starts, 2)
    assert np.bincount(ray, minlength=4).tolist() == [2, 1, 0, 1]
    np.testing.assert_allclose(height[ray == 3], [0.03], atol=1e-15)


def test_occupancy_of_points_on_a_box_grid_and_off_it():
    """Points on the lines through a box's edges and corners, and random ones."""
    box = trimesh.creation.box(extents=(0.08, 0.08, 0.08))
    grid = np.stack(np.meshgrid(*[np.linspace(-0.06, 0.06, 13)] * 3, indexing="ij"), -1)
    scattered = np.random.default_rng(6).uniform(-0.06, 0.06, (3000, 3))
    points = np.concatenate([grid.reshape(-1, 3), scattered])
    inside = np.all(np.abs(points) < 0.04 - 1e-12, axis=1)
    clear = np.all(np.abs(np.abs(points) - 0.04) > 1e-12, axis=1)  # not on the surface
    occupied = mesh_occupancy(points, box.vertices, box.faces)
    np.testing.assert_array_equal(occupied[clear], inside[clear])
