"""The model as an asset: its surface, mass properties, collision parts and symmetry,
each checked against hand-computed solids and finite differences."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pipeline.asset.collision import convex_parts
from pipeline.asset.mass import is_closed, mass_properties, signed_volume
from pipeline.asset.meshing import View, close_model, half_widths, surface
from pipeline.asset.symmetry import export_symmetry, object_frame, plane_jacobian, reflection
from pipeline.metrics.fits import plane_after_bias
from pipeline.types import Bias, SymmetryPlane


def _seen(mesh: trimesh.Trimesh, count: int, seed: int, noise_m: float = 0.0) -> np.ndarray:
    """What a camera in front (-x) and above sees of ``mesh``, mirrored about x = 0, with
    noise, and nothing of the last ``cut`` above the table (the segmenter's cut)."""
    rng = np.random.default_rng(seed)
    points, faces = trimesh.sample.sample_surface(mesh, count, seed=seed)
    normals = mesh.face_normals[faces]
    view = normals @ np.array([-0.6, 0.0, 0.8]) > 0.05
    points = points[view & (points[:, 2] > 0.012)]
    points = points + rng.normal(0.0, noise_m, points.shape)
    return np.concatenate([points, points * [-1.0, 1.0, 1.0]])


def _standing(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    return mesh.apply_translation([0.0, 0.0, -mesh.bounds[0, 2]])


@pytest.mark.parametrize("noise_m", [0.0, 0.0015])
def test_a_box_seen_from_one_side_closes_into_its_volume(noise_m):
    box = _standing(trimesh.creation.box((0.042, 0.15, 0.10)))
    mesh = close_model(_seen(box, 40_000, seed=1, noise_m=noise_m))
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert signed_volume(mesh) == pytest.approx(box.volume, rel=0.05)
    assert mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)  # closed flat on the table
    # The base is flat: most of the footprint is faces on the table (the blur rounds the
    # edges by about a cell).
    on_table = np.all(mesh.vertices[mesh.faces][:, :, 2] == 0.0, axis=1)
    assert mesh.area_faces[on_table].sum() > 0.75 * 0.042 * 0.15


def test_a_cylinder_closes_into_its_volume_and_shape():
    cylinder = _standing(trimesh.creation.cylinder(0.035, 0.12, sections=64))
    mesh = close_model(_seen(cylinder, 40_000, seed=2, noise_m=0.001))
    assert mesh.is_watertight
    assert signed_volume(mesh) == pytest.approx(np.pi * 0.035**2 * 0.12, rel=0.06)
    side = mesh.vertices[(mesh.vertices[:, 2] > 0.02) & (mesh.vertices[:, 2] < 0.1)]
    radius = np.hypot(side[:, 0], side[:, 1])
    assert np.median(radius) == pytest.approx(0.035, abs=0.001)


def test_holes_in_the_view_and_stray_points_do_not_open_the_surface():
    box = _standing(trimesh.creation.box((0.05, 0.12, 0.08)))
    points = _seen(box, 30_000, seed=3)
    hole = (np.abs(points[:, 1]) < 0.01) & (np.abs(points[:, 2] - 0.04) < 0.01)
    stray = np.array([[0.0, 0.3, 0.05], [0.01, 0.3, 0.05]])
    mesh = close_model(np.concatenate([points[~hole], stray]))
    assert mesh.is_watertight
    assert signed_volume(mesh) == pytest.approx(box.volume, rel=0.05)
    assert mesh.bounds[1, 1] < 0.07  # the speck far away is left out


def test_too_few_points_is_an_error():
    with pytest.raises(ValueError, match="at least 4"):
        close_model(np.array([[0.0, 0.0, 0.01], [0.01, 0.0, 0.01]]))


def test_mass_properties_of_a_box_match_the_textbook():
    a, b, c = 0.04, 0.1, 0.2
    box = trimesh.creation.box((a, b, c)).apply_translation([0.1, -0.2, 0.3])
    props = mass_properties(box, density_kg_m3=700.0)
    mass = 700.0 * a * b * c
    assert props.volume_m3 == pytest.approx(a * b * c, rel=1e-9)
    assert props.mass_kg == pytest.approx(mass, rel=1e-9)
    assert props.centre_of_mass_m == pytest.approx([0.1, -0.2, 0.3], abs=1e-12)
    expected = mass / 12.0 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    assert props.inertia_kg_m2 == pytest.approx(expected, rel=1e-9, abs=1e-15)


def test_a_given_mass_sets_the_density():
    cylinder = trimesh.creation.cylinder(0.03, 0.1, sections=256)
    props = mass_properties(cylinder, density_kg_m3=1.0, mass_kg=0.5)
    assert props.mass_kg == pytest.approx(0.5)
    # A solid cylinder about its axis: m r^2 / 2 (the 256-gon is 0.01 % short of it).
    assert props.inertia_kg_m2[2, 2] == pytest.approx(0.5 * 0.5 * 0.03**2, rel=1e-3)
    assert props.density_kg_m3 == pytest.approx(0.5 / cylinder.volume)


def test_mass_properties_need_a_closed_mesh():
    open_box = trimesh.creation.box((0.1, 0.1, 0.1))
    open_box.update_faces(np.arange(len(open_box.faces)) > 0)
    with pytest.raises(ValueError, match="watertight"):
        mass_properties(open_box, 500.0)


def _l_shape() -> np.ndarray:
    """A drill-like L: a 0.05 x 0.05 x 0.15 post and a 0.05 x 0.15 x 0.04 body on top."""
    post = trimesh.creation.box((0.05, 0.05, 0.15)).apply_translation([0, 0, 0.075])
    body = trimesh.creation.box((0.05, 0.15, 0.04)).apply_translation([0, 0.05, 0.17])
    union = trimesh.boolean.union([post, body], engine="manifold")
    points, _ = trimesh.sample.sample_surface(union, 60_000, seed=4)
    return union, points[points[:, 2] > 0.005]


def test_collision_parts_are_convex_cover_the_solid_and_stay_in_its_box():
    union, points = _l_shape()
    solid = half_widths(points)
    mesh = surface(solid)
    parts = convex_parts(solid, mesh.bounds)
    assert len(parts) >= 2  # the L is not convex
    for part in parts:
        assert part.is_watertight and part.is_convex and signed_volume(part) > 0.0
        assert np.all(part.bounds[0] >= mesh.bounds[0] - 0.002)
        assert np.all(part.bounds[1] <= mesh.bounds[1] + 0.002)
    # The parts hold the solid and little more: points inside the true L (2 mm from its
    # faces) are inside some part.
    rng = np.random.default_rng(5)
    inside = np.concatenate(
        [
            rng.uniform([-0.023, -0.023, 0.002], [0.023, 0.023, 0.148], (2000, 3)),
            rng.uniform([-0.023, -0.023, 0.152], [0.023, 0.123, 0.188], (2000, 3)),
        ]
    )
    covered = np.zeros(len(inside), dtype=bool)
    for part in parts:
        covered |= part.contains(inside)
    assert covered.mean() > 0.97
    total = sum(part.volume for part in parts)
    assert total < 1.25 * union.volume


def test_plane_jacobian_matches_finite_differences():
    plane = SymmetryPlane(0.4, 0.03)
    bias = Bias(0.05, np.array([0.01, -0.02, 0.003]), np.array([0.5, 0.1, 0.08]))
    state = np.array([bias.yaw_rad, *bias.translation_m, plane.offset_m, plane.theta_rad])

    def moved(g):
        after = plane_after_bias(SymmetryPlane(g[5], g[4]), Bias(g[0], g[1:4], bias.pivot_m))
        return np.array([after.theta_rad, after.offset_m])

    step = 1e-6
    numeric = np.column_stack(
        [(moved(state + step * e) - moved(state - step * e)) / (2 * step) for e in np.eye(6)]
    )
    assert plane_jacobian(plane, bias) == pytest.approx(numeric, abs=1e-8)


def test_the_object_frame_puts_the_plane_at_x_zero_and_carries_its_covariance():
    plane = SymmetryPlane(1.1, 0.2)
    bias = Bias()
    covariance = np.diag([1e-4, 1e-6, 1e-6, 1e-6, 4e-6, 3e-4])
    centre = np.array([0.3, 0.4, 0.1])
    export = export_symmetry(plane, bias, covariance, centre, table_z_m=0.02)
    transform = export.T_robot_object
    assert np.allclose(transform[:3, :3].T @ transform[:3, :3], np.eye(3))
    assert transform[2, 3] == pytest.approx(0.02)
    on_plane = plane.mirror(np.array([[0.7, -0.1, 0.3]])) * 0.5 + 0.5 * np.array([0.7, -0.1, 0.3])
    local = (on_plane - transform[:3, 3]) @ transform[:3, :3]
    assert local[0, 0] == pytest.approx(0.0, abs=1e-12)
    # The object-frame offset of a perturbed plane, by finite differences through the frame.
    origin, axis = transform[:3, 3], transform[:3, 0]

    def local_plane(theta, offset):
        normal = np.array([np.cos(theta), np.sin(theta), 0.0])
        return [np.arctan2(normal @ transform[:3, 1], normal @ axis), offset - normal @ origin]

    step = 1e-6
    jac = np.column_stack(
        [
            (np.subtract(local_plane(1.1 + step, 0.2), local_plane(1.1 - step, 0.2))) / (2 * step),
            (np.subtract(local_plane(1.1, 0.2 + step), local_plane(1.1, 0.2 - step))) / (2 * step),
        ]
    )
    expected = jac @ export.covariance_robot @ jac.T
    assert export.covariance_object == pytest.approx(expected, rel=1e-6)
    # Without a bias: theta' = m_theta + b_theta, r' = m_r + n . t.
    assert export.covariance_robot == pytest.approx(np.diag([4e-4, 5e-6]), rel=1e-9, abs=1e-15)


def test_reflections_are_the_plane_mirror_and_bop_gets_the_object_frame_one():
    plane = SymmetryPlane(-0.7, 0.05)
    points = np.random.default_rng(6).normal(size=(5, 3))
    matrix = reflection(plane.normal, plane.offset_m)
    mirrored = points @ matrix[:3, :3].T + matrix[:3, 3]
    assert mirrored == pytest.approx(plane.mirror(points))
    export = export_symmetry(plane, Bias(), None, np.zeros(3), 0.0)
    assert export.covariance_robot is None
    bop = export.to_json()["bop"]["symmetries_discrete"]
    assert bop == [[-1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]]
    assert object_frame(plane, np.zeros(3), 0.0)[:3, 0] == pytest.approx(plane.normal)


def test_the_closed_mesh_check_agrees_with_trimesh():
    box = trimesh.creation.box((0.1, 0.2, 0.3))
    assert is_closed(box) and box.is_watertight and box.is_winding_consistent
    holed = box.copy()
    holed.update_faces(np.arange(len(box.faces)) > 0)
    assert not is_closed(holed) and not holed.is_watertight
    flipped = box.copy()
    flipped.faces[0] = flipped.faces[0][::-1]
    assert not is_closed(flipped) and not flipped.is_winding_consistent
    two = trimesh.util.concatenate([box, box.copy().apply_translation([1.0, 0.0, 0.0])])
    assert is_closed(two) and two.is_watertight


def _camera_view(mesh: trimesh.Trimesh, camera: np.ndarray, seed: int) -> np.ndarray:
    """The points of ``mesh`` a camera at ``camera`` sees (the first surface along each
    line of sight), above the segmenter's cut."""
    points, _ = trimesh.sample.sample_surface(mesh, 60_000, seed=seed)
    directions = points - camera
    distances = np.linalg.norm(directions, axis=1)
    hits, rays, _ = mesh.ray.intersects_location(
        np.tile(camera, (len(points), 1)), directions / distances[:, None]
    )
    first = np.full(len(points), np.inf)
    np.minimum.at(first, rays, np.linalg.norm(hits - camera, axis=1))
    seen = points[(distances <= first + 1e-6) & (points[:, 2] > 0.012)]
    return seen


def test_a_box_seen_along_its_plane_is_closed_under_its_top_with_the_view():
    """Looking along the plane the camera sees the top and the near end, no side wall: the
    region under the top is hidden, and the camera's view says so."""
    box = _standing(trimesh.creation.box((0.10, 0.20, 0.08)))
    camera = np.array([0.0, 0.6, 0.5])
    seen = _camera_view(box, camera, seed=7)
    completed = np.concatenate([seen, seen * [-1.0, 1.0, 1.0]])
    # Without the view only the top and the near end are solid: layers a cell thin.
    with pytest.raises(ValueError, match="encloses no solid"):
        close_model(completed)
    with_view = close_model(completed, view=View(camera, seen))
    assert with_view.is_watertight
    assert signed_volume(with_view) == pytest.approx(box.volume, rel=0.06)


def test_an_overhang_the_camera_sees_under_stays_open():
    union, _ = _l_shape()
    camera = np.array([-0.6, 0.0, 0.45])
    seen = _camera_view(union, camera, seed=8)
    completed = np.concatenate([seen, seen * [-1.0, 1.0, 1.0]])
    mesh = close_model(completed, view=View(camera, seen))
    assert mesh.is_watertight
    assert signed_volume(mesh) == pytest.approx(union.volume, rel=0.08)
    # Under the body, beyond the post, the table is free.
    assert not mesh.contains([[0.0, 0.1, 0.05]])[0]
