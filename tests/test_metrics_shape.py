"""Chamfer distance, F-score and volumetric IoU against hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from pipeline.metrics import (
    MeshSurface,
    grid_order,
    hull_iou,
    mesh_occupancy,
    nearest_distances,
    point_to_mesh_distances,
    sample_surface,
    solid_grid,
    solid_share_inside,
    support_faces,
    surface_scores,
)


def _fibonacci_sphere(count: int, radius: float) -> np.ndarray:
    """``count`` nearly evenly spread points on a sphere about the origin."""
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    azimuth = math.pi * (1.0 + math.sqrt(5.0)) * k
    ring = np.sqrt(1.0 - z * z)
    return radius * np.column_stack([ring * np.cos(azimuth), ring * np.sin(azimuth), z])


def test_scores_of_three_points_by_hand():
    """Model {0}, truth {0, 4 mm}: the model is all right (precision 1) but covers half of
    the truth within 2 mm; Chamfer = (0 + (0 + 4) / 2) / 2 = 1 mm."""
    model = np.zeros((1, 3))
    truth = np.array([[0.0, 0.0, 0.0], [0.004, 0.0, 0.0]])
    scores = surface_scores(nearest_distances(model, truth), nearest_distances(truth, model))
    assert scores["chamfer_mm"] == pytest.approx(1.0)
    assert scores["precision_2mm"] == 1.0
    assert scores["recall_2mm"] == 0.5
    assert scores["fscore_2mm"] == pytest.approx(2.0 / 3.0)
    assert scores["fscore_5mm"] == 1.0


def test_two_concentric_spheres_are_their_radius_difference_apart():
    """Both spheres carry points along the same directions, so every point's nearest
    neighbour on the other sphere is the radial one, 3 mm away: Chamfer 3 mm, nothing within
    2 mm (F 0), everything within 5 mm (F 1)."""
    inner, outer = _fibonacci_sphere(4000, 0.050), _fibonacci_sphere(4000, 0.053)
    scores = surface_scores(nearest_distances(inner, outer), nearest_distances(outer, inner))
    assert scores["chamfer_mm"] == pytest.approx(3.0, abs=1e-9)
    assert scores["precision_2mm"] == scores["recall_2mm"] == scores["fscore_2mm"] == 0.0
    assert scores["fscore_5mm"] == 1.0


def test_no_correct_point_gives_f_zero_not_nan():
    scores = surface_scores(np.full(3, 0.1), np.full(4, 0.1))
    assert scores["fscore_2mm"] == 0.0


# A cube of side A shifted by D along x: the hand-computed shares below are exact for the
# exact point-to-surface distances of points spread uniformly over the shifted surface.
A, D = 0.1, 0.01


def _cube_share_within(tau: float) -> float:
    """Share of the shifted cube's surface within ``tau`` (< D) of the cube: the four side
    faces up to the cube's edge (4 A (A - D)), their strip beyond it up to ``tau`` (4 A tau),
    and the face moved inside where it is within ``tau`` of a side face; the face moved
    outside is D away."""
    inside_face = A * A - (A - 2.0 * tau) ** 2
    return (4.0 * A * (A - D) + 4.0 * A * tau + inside_face) / (6.0 * A * A)


def _cube_mean_distance() -> float:
    """Mean distance of the shifted cube's surface to the cube: the side strips (mean D/2),
    the face outside (D), and the face inside, where a point u from the nearest edge is
    min(D, u) away: its mean is (A^3 - (A - 2D)^3) / (6 A^2)."""
    strips = 4.0 * A * D * D / 2.0
    outside = A * A * D
    inside = (A**3 - (A - 2.0 * D) ** 3) / 6.0
    return (strips + outside + inside) / (6.0 * A * A)


def test_a_shifted_cube_by_hand():
    cube = trimesh.creation.box(extents=(A, A, A))
    shift = np.array([D, 0.0, 0.0])
    samples = np.asarray(trimesh.sample.sample_surface(cube, 200_000, seed=3)[0])
    model = samples + shift  # uniform on the shifted cube's surface
    truth = np.asarray(trimesh.sample.sample_surface(cube, 200_000, seed=4)[0])
    to_truth = point_to_mesh_distances(model, cube.vertices, cube.faces)
    to_model = point_to_mesh_distances(truth, cube.vertices + shift, cube.faces)
    scores = surface_scores(to_truth, to_model)
    assert scores["chamfer_mm"] == pytest.approx(_cube_mean_distance() * 1e3, rel=0.01)
    for tau, label in ((0.002, "2mm"), (0.005, "5mm")):
        expected = _cube_share_within(tau)
        # The configuration is its own mirror image: precision and recall are equal.
        assert scores[f"precision_{label}"] == pytest.approx(expected, abs=0.005)
        assert scores[f"recall_{label}"] == pytest.approx(expected, abs=0.005)
        assert scores[f"fscore_{label}"] == pytest.approx(expected, abs=0.005)


def test_iou_of_a_shifted_cube_is_overlap_over_union():
    """Two cubes of side A, D apart: IoU = (A - D) / (A + D)."""
    cube = trimesh.creation.box(extents=(A, A, A))
    solid = solid_grid(cube.vertices, cube.faces)
    assert solid.volume_m3 == pytest.approx(A**3, rel=0.01)
    shift = 0.0123
    corners = cube.vertices + np.array([shift, 0.0, 0.0])
    assert hull_iou(corners, solid) == pytest.approx((A - shift) / (A + shift), abs=0.01)
    assert hull_iou(cube.vertices, solid) == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("extents", [(0.045, 0.171, 0.146), (0.03, 0.05, 0.2)])
def test_iou_of_a_solid_with_its_own_hull_never_exceeds_one(extents):
    """A box's hull is the box: its counted solid may exceed the hull's exact volume by the
    grid's error, and the IoU must still be at most 1."""
    box = trimesh.creation.box(extents=extents)
    box.apply_transform(trimesh.transformations.rotation_matrix(0.3, [0.0, 0.0, 1.0]))
    iou = hull_iou(box.vertices, solid_grid(box.vertices, box.faces))
    assert 0.98 <= iou <= 1.0


def test_iou_of_two_overlapping_spheres_is_the_lens_over_the_union():
    """Spheres of radius R with centres d apart overlap in a lens of volume
    pi (4R + d) (2R - d)^2 / 12."""
    radius, distance = 0.05, 0.03
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    solid = solid_grid(sphere.vertices, sphere.faces)
    lens = math.pi * (4 * radius + distance) * (2 * radius - distance) ** 2 / 12.0
    ball = 4.0 / 3.0 * math.pi * radius**3
    moved = sphere.vertices + np.array([0.0, 0.0, distance])
    assert hull_iou(moved, solid) == pytest.approx(lens / (2 * ball - lens), abs=0.01)
    apart = sphere.vertices + np.array([3 * radius, 0.0, 0.0])
    assert hull_iou(apart, solid) == 0.0


def test_flat_points_have_no_volume():
    cube = trimesh.creation.box(extents=(A, A, A))
    flat = np.random.default_rng(0).uniform(-0.05, 0.05, (100, 3)) * [1.0, 1.0, 0.0]
    assert hull_iou(flat, solid_grid(cube.vertices, cube.faces)) == 0.0


def test_occupancy_inside_and_outside_a_box():
    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    offset = np.array([0.7, -0.3, 0.2])  # away from the origin: float32 handling matters
    points = np.random.default_rng(2).uniform(-0.2, 0.2, (5000, 3))
    inside = np.all(np.abs(points) < [0.05, 0.1, 0.15], axis=1)
    occupied = mesh_occupancy(points + offset, box.vertices + offset, box.faces)
    np.testing.assert_array_equal(occupied, inside)


def test_surface_samples_leave_out_the_face_the_object_stands_on():
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    box.apply_translation([0.4, 0.0, 0.05])  # standing on z = 0
    support = support_faces(box.vertices, box.faces)
    assert support.sum() == 2  # the bottom square's two triangles
    assert np.allclose(box.triangles_center[support][:, 2], 0.0)
    points = sample_surface(box.vertices, box.faces, 5000, seed=7)
    assert np.all(points[:, 2] > 1e-9)  # nothing on the bottom face
    assert np.mean(points[:, 2] > 0.1 - 1e-9) == pytest.approx(1.0 / 5.0, abs=0.02)
    again = sample_surface(box.vertices, box.faces, 5000, seed=7)
    np.testing.assert_array_equal(points, again)


def _tilted(mesh: trimesh.Trimesh, seed: int) -> trimesh.Trimesh:
    """``mesh`` turned about a random axis and moved away from the origin."""
    rng = np.random.default_rng(seed)
    turn = trimesh.transformations.random_rotation_matrix(rng.random(3))
    turn[:3, 3] = [0.6, -0.2, 0.1]
    return mesh.copy().apply_transform(turn)


@pytest.mark.parametrize(
    "mesh",
    [
        _tilted(trimesh.creation.box(extents=(0.17, 0.146, 0.042)), 1),
        _tilted(trimesh.creation.cylinder(radius=0.03, height=0.1, sections=48), 2),
        _tilted(trimesh.creation.annulus(r_min=0.02, r_max=0.04, height=0.05), 3),
    ],
    ids=["box", "cylinder", "annulus"],
)
def test_solid_and_iou_match_the_per_cell_inside_test(mesh):
    """The line-of-cells parity votes and the hull's column spans give the solid and the IoU
    that testing every cell centre on its own (:func:`mesh_occupancy`) gives."""
    solid = solid_grid(mesh.vertices, mesh.faces, max_cells=200_000)
    shape = solid.inside.shape
    axes = [solid.origin_m[i] + solid.pitch_m * np.arange(shape[i]) for i in range(3)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    reference = mesh_occupancy(centres, mesh.vertices, mesh.faces).reshape(shape)
    assert np.count_nonzero(solid.inside != reference) <= 1e-4 * reference.sum()
    assert solid.volume_m3 == pytest.approx(mesh.volume, rel=0.02)

    rng = np.random.default_rng(5)
    model = sample_surface(mesh.vertices, mesh.faces, 3000, skip_support=False)
    model += rng.normal(0.0, 0.004, model.shape) + np.array([0.01, 0.0, 0.005])
    hull = trimesh.convex.convex_hull(model)
    in_hull = mesh_occupancy(solid.cells, hull.vertices, hull.faces)
    intersection = np.count_nonzero(in_hull) * solid.cell_volume_m3
    expected = intersection / (hull.volume + solid.volume_m3 - intersection)
    assert 0.2 < expected < 0.95
    assert hull_iou(model, solid) == pytest.approx(expected, abs=1e-4)


@pytest.mark.parametrize("seed", [1, 2])
def test_share_of_a_solid_inside_a_mesh_matches_the_per_cell_inside_test(seed):
    """The column spans of :func:`solid_share_inside` count the solid's cells that testing
    every cell centre on its own (:func:`mesh_occupancy`) finds inside a non-convex mesh."""
    truth = _tilted(trimesh.creation.box(extents=(0.12, 0.1, 0.06)), seed)
    ring = _tilted(trimesh.creation.annulus(r_min=0.02, r_max=0.05, height=0.07), seed + 10)
    ring.apply_translation(truth.centroid - ring.centroid)
    solid = solid_grid(truth.vertices, truth.faces, max_cells=100_000)
    inside = mesh_occupancy(solid.cells, ring.vertices, ring.faces)
    share = solid_share_inside(MeshSurface(ring.vertices, ring.faces), solid)
    assert 0.1 < share < 0.9
    assert share == pytest.approx(np.mean(inside), abs=1e-4)


def test_share_inside_tests_the_cells_of_an_odd_column_one_by_one():
    """Rays up through a box open at the top cross it once: each such column's cells are
    tested on their own, so the share is the per-cell test's, not the parity's 0."""
    solid = solid_grid(*_box_arrays((0.04, 0.04, 0.02)), max_cells=20_000)
    cup = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    open_top = cup.faces[cup.triangles_center[:, 2] < 0.049]
    share = solid_share_inside(MeshSurface(cup.vertices, open_top), solid)
    inside = mesh_occupancy(solid.cells, cup.vertices, open_top)
    assert share == np.mean(inside)
    assert share > 0.0


def _box_arrays(extents: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    box = trimesh.creation.box(extents=extents)
    return np.asarray(box.vertices), np.asarray(box.faces)


def test_sample_distances_asked_in_grid_order_are_each_samples_own():
    """:meth:`GroundTruth.sample_distances` asks in :func:`grid_order` (a permutation that
    keeps neighbours together) and returns every sample's value in the samples' order."""
    from pipeline.metrics.evaluation import GroundTruth

    box = _tilted(trimesh.creation.box(extents=(0.08, 0.05, 0.1)), 4)
    truth = GroundTruth(np.asarray(box.vertices), np.asarray(box.faces), "none", None, np.zeros(2))
    samples = truth.surface_samples
    order = grid_order(samples)
    np.testing.assert_array_equal(np.sort(order), np.arange(len(samples)))
    steps = np.linalg.norm(np.diff(samples[order], axis=0), axis=1)
    assert np.median(steps) < 0.25 * np.median(np.linalg.norm(np.diff(samples, axis=0), axis=1))
    model = np.random.default_rng(3).uniform(-0.05, 0.05, (500, 3)) + box.centroid
    np.testing.assert_array_equal(
        truth.sample_distances(lambda queries: nearest_distances(queries, model)),
        nearest_distances(samples, model),
    )
