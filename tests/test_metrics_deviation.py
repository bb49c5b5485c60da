"""Point-to-mesh deviation against analytic distances."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pipeline.metrics import mesh_deviation, point_to_mesh_distances


def _box_distance(points: np.ndarray, half_extents: np.ndarray) -> np.ndarray:
    """Exact unsigned distance to the surface of an axis-aligned box centred at the origin."""
    q = np.abs(points) - half_extents
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    inside = np.minimum(q.max(axis=1), 0.0)
    return outside + np.abs(inside)


def test_distances_to_a_box_inside_and_outside():
    half = np.array([0.05, 0.1, 0.15])
    mesh = trimesh.creation.box(extents=2 * half)
    offset = np.array([0.6, -0.2, 0.15])  # away from the origin: float32 handling matters
    points = np.random.default_rng(0).uniform(-0.25, 0.25, (5000, 3))
    distances = point_to_mesh_distances(points + offset, mesh.vertices + offset, mesh.faces)
    np.testing.assert_allclose(distances, _box_distance(points, half), atol=1e-6)


def test_distances_to_a_sphere():
    radius = 0.05
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    rng = np.random.default_rng(1)
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    rho = rng.uniform(0.01, 0.12, 2000)
    distances, summary = mesh_deviation(directions * rho[:, None], mesh.vertices, mesh.faces)
    # Faceting: flat triangles lie at most R (1 - cos(edge / R)) inside the sphere (~0.02 mm).
    edge = mesh.edges_unique_length.max()
    sagitta = radius * (1.0 - np.cos(edge / radius))
    np.testing.assert_allclose(distances, np.abs(rho - radius), atol=sagitta + 1e-6)
    assert summary.max == pytest.approx(np.abs(rho - radius).max(), abs=sagitta + 1e-6)
    assert summary.count == 2000


def test_rejects_bad_shapes():
    mesh = trimesh.creation.box()
    with pytest.raises(ValueError, match="shape"):
        point_to_mesh_distances(np.zeros((3, 2)), mesh.vertices, mesh.faces)
