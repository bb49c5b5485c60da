"""The object catalogue: watertight, placed, sized as the paper says, symmetric as recorded."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from pipeline.catalogue import objects as catalogue
from pipeline.catalogue.objects import list_objects, load_object
from pipeline.errors import InputError

PAPER_OBJECTS = {
    "cd_drive", "plastic_case", "salt_cylinder", "spray_bottle",
    "box", "bread", "coffee", "cup", "jam", "salt_cylinder_kth", "saltbox", "sedan",
}  # fmt: skip
NAMES = sorted(PAPER_OBJECTS)
PG70_APERTURE_M = 0.065  # datasheet: usable aperture with tactile pads


def surface_samples(mesh: trimesh.Trimesh, count: int = 1500) -> np.ndarray:
    points, _ = trimesh.sample.sample_surface(mesh, count, seed=7)
    return points


def distance_to_surface(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    _, distance, _ = trimesh.proximity.closest_point(mesh, points)
    return distance


def mirrored(points: np.ndarray, normal_xy, offset_m: float) -> np.ndarray:
    """Reflect through the vertical plane {n . (x, y) = offset}, n normalised here."""
    normal = np.array([normal_xy[0], normal_xy[1], 0.0])
    normal /= np.linalg.norm(normal)
    return points - 2.0 * (points @ normal - offset_m)[:, None] * normal


def test_the_catalogue_lists_the_papers_objects():
    assert {info.name for info in list_objects()} == PAPER_OBJECTS
    for info in list_objects():
        assert info.description and info.reference
        assert info.paper_set in ("parallel-jaw", "three-finger")
        assert (info.symmetry_plane is not None) == (info.symmetry == "planar")


@pytest.mark.parametrize("name", NAMES)
def test_every_mesh_is_a_closed_solid_on_the_table_centred_in_xy(name):
    mesh = load_object(name).mesh
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.body_count == 1
    assert mesh.volume > 0.0
    lower, upper = mesh.bounds
    assert lower[2] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose((lower[:2] + upper[:2]) / 2.0, 0.0, atol=1e-12)


@pytest.mark.parametrize(
    ("name", "axis", "paper_m"),
    [("cd_drive", 0, 0.042), ("plastic_case", 0, 0.044), ("salt_cylinder", 0, 0.053),
     ("salt_cylinder", 1, 0.053)],
)  # fmt: skip
def test_the_papers_measured_dimensions(name, axis, paper_m):
    assert load_object(name).mesh.extents[axis] == pytest.approx(paper_m, abs=1e-9)


def test_box_and_cylinder_volumes_match_the_analytic_solids():
    drive = load_object("cd_drive")
    d = drive.dimensions_m
    assert drive.mesh.volume == pytest.approx(d["thickness"] * d["length"] * d["height"], rel=1e-12)
    salt = load_object("salt_cylinder")
    radius, height, n = salt.dimensions_m["diameter"] / 2, salt.dimensions_m["height"], 128
    inscribed_polygon_area = 0.5 * n * radius**2 * np.sin(2.0 * np.pi / n)
    assert salt.mesh.volume == pytest.approx(inscribed_polygon_area * height, rel=1e-9)
    assert salt.mesh.volume == pytest.approx(np.pi * radius**2 * height, rel=1e-3)


@pytest.mark.parametrize("name", [i.name for i in list_objects() if i.symmetry == "planar"])
def test_planar_objects_are_mirror_symmetric_about_the_recorded_plane(name):
    obj = load_object(name)
    plane = obj.symmetry_plane
    vertices = obj.mesh.vertices
    vertex_images = mirrored(vertices, plane.normal[:2], plane.offset_m)
    assert cKDTree(vertices).query(vertex_images)[0].max() < 1e-12
    # Mirrored non-planar quads are split along the other diagonal: tens of micrometres.
    reflected = mirrored(surface_samples(obj.mesh), plane.normal[:2], plane.offset_m)
    assert distance_to_surface(obj.mesh, reflected).max() < 5e-5


@pytest.mark.parametrize("name", [i.name for i in list_objects() if i.symmetry == "rotational"])
def test_rotational_objects_are_symmetric_about_any_vertical_plane_through_z(name):
    obj = load_object(name)
    points = surface_samples(obj.mesh)
    radius = obj.mesh.extents[0] / 2.0
    chord_sag = radius * (1.0 - np.cos(np.pi / 128))  # polygonal approximation of a circle
    for angle in (0.3, 1.1):
        reflected = mirrored(points, (np.cos(angle), np.sin(angle)), 0.0)
        assert distance_to_surface(obj.mesh, reflected).max() < 2.0 * chord_sag


def test_spray_bottle_has_one_mirror_plane_and_fits_the_parallel_jaw_gripper():
    bottle = load_object("spray_bottle")
    points = surface_samples(bottle.mesh)
    across_plane = mirrored(points, (1.0, 0.0), 0.0)  # front/back: nozzle vs. back of head
    assert distance_to_surface(bottle.mesh, across_plane).max() > 0.01
    rotated = points @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T
    assert distance_to_surface(bottle.mesh, rotated).max() > 0.01
    assert bottle.symmetry_plane.normal[:2] == pytest.approx([0.0, 1.0])
    assert bottle.mesh.extents[1] < PG70_APERTURE_M


def test_the_parallel_jaw_objects_fit_the_pg70_across_their_symmetry_plane():
    for info in list_objects():
        if info.paper_set == "parallel-jaw" and info.symmetry_plane is not None:
            normal = info.symmetry_plane.normal
            extent_along_normal = np.ptp(load_object(info.name).mesh.vertices @ normal)
            assert extent_along_normal < PG70_APERTURE_M, info.name


def test_cup_is_open_with_its_floor_at_the_base_thickness():
    cup = load_object("cup")
    d = cup.dimensions_m
    axis_x = cup.mesh.bounds[0][0] + d["diameter"] / 2.0  # the body is the -x end of the box
    hits, _, _ = cup.mesh.ray.intersects_location([[axis_x, 0.0, 1.0]], [[0.0, 0.0, -1.0]])
    assert hits[:, 2].max() == pytest.approx(d["base"], abs=1e-9)


def test_meshes_are_deterministic_and_callers_get_copies():
    first = load_object("sedan").mesh
    first.apply_translation([1.0, 0.0, 0.0])
    again = load_object("sedan").mesh
    assert again.bounds[0][0] == pytest.approx(-0.08)
    catalogue._generated_mesh.cache_clear()
    regenerated = load_object("sedan").mesh
    np.testing.assert_array_equal(regenerated.vertices, again.vertices)
    np.testing.assert_array_equal(regenerated.faces, again.faces)


def test_unknown_name_lists_the_catalogue():
    with pytest.raises(InputError, match=r"unknown object 'teapot'.*cd_drive.*sedan"):
        load_object("teapot")


def test_mesh_files_load_recentred_unless_asked_not_to(tmp_path):
    path = tmp_path / "brick.stl"
    brick = trimesh.creation.box(extents=[0.02, 0.04, 0.06])
    brick.apply_translation([1.0, 2.0, 3.0])
    brick.export(path)
    loaded = load_object(str(path))
    assert loaded.name == "brick" and loaded.source == str(path) and loaded.symmetry == "none"
    assert loaded.watertight
    expected = [[-0.01, -0.02, 0.0], [0.01, 0.02, 0.06]]
    np.testing.assert_allclose(loaded.mesh.bounds, expected, atol=1e-6)  # STL is float32
    assert loaded.dimensions_m == pytest.approx({"extent_x": 0.02, "extent_y": 0.04,
                                                 "extent_z": 0.06}, abs=1e-6)  # fmt: skip
    kept = load_object(path, recentre=False)
    np.testing.assert_allclose(kept.mesh.bounds, [[0.99, 1.98, 2.97], [1.01, 2.02, 3.03]],
                               atol=1e-6)  # fmt: skip


def test_an_open_scan_is_accepted_and_flagged(tmp_path):
    path = tmp_path / "open_scan.ply"
    open_box = trimesh.creation.box(extents=[0.03, 0.03, 0.03])
    open_box.update_faces(np.arange(len(open_box.faces)) > 1)  # drop one side's two triangles
    open_box.export(path)
    loaded = load_object(str(path))
    assert not loaded.watertight
    assert len(loaded.mesh.faces) == 10


def test_a_scan_with_nan_normals_loads_without_a_warning(tmp_path):
    # A tetrahedron whose OBJ gives one face a NaN normal, as the YCB mug scan does.
    path = tmp_path / "nan_normal.obj"
    path.write_text(
        "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nv 0 0 0.05\n"
        "vn 0 0 -1\nvn nan nan nan\nvn 1 1 1\nvn 0 -1 0\n"
        "f 1//1 3//1 2//1\nf 1//4 2//4 4//4\nf 1//2 4//2 3//2\nf 2//3 3//3 4//3\n"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = load_object(str(path))
    assert len(loaded.mesh.faces) == 4 and np.isfinite(loaded.mesh.vertices).all()


def test_missing_unreadable_or_unsupported_files_name_the_path(tmp_path):
    missing = tmp_path / "nothing.obj"
    with pytest.raises(InputError, match=r"nothing\.obj: no such mesh file"):
        load_object(str(missing))
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(b"\x00\x01 definitely not an STL")
    with pytest.raises(InputError, match=r"garbage\.stl"):
        load_object(str(garbage))
    notes = tmp_path / "notes.txt"
    notes.write_text("hello")
    with pytest.raises(InputError, match=r"notes\.txt: unsupported mesh format"):
        load_object(str(notes))


@pytest.mark.parametrize(("units", "scale"), [("m", 1.0), ("mm", 1e3)])
def test_a_mesh_s_true_plane_is_given_in_its_own_frame_and_units(tmp_path, units, scale):
    # A 40 x 60 x 100 mm box whose file puts its centre at (0.2, -0.1) and whose mirror
    # plane there is turned 30 deg: after placing, the plane turns the same and passes
    # through the centre, the bounding box's.
    box = trimesh.creation.box((0.04, 0.06, 0.1))
    box.apply_translation((0.2, -0.1, 0.05))
    box.apply_scale(scale)
    box.export(tmp_path / "box.stl")
    normal = np.array([np.cos(np.radians(30.0)), np.sin(np.radians(30.0))])
    offset = normal @ np.array([0.2, -0.1]) * scale
    obj = load_object(tmp_path / "box.stl", units=units, symmetry=(*(2.0 * normal), 2.0 * offset))
    assert obj.symmetry == "planar"
    assert np.degrees(obj.symmetry_plane.theta_rad) == pytest.approx(30.0)
    assert obj.symmetry_plane.offset_m == pytest.approx(0.0, abs=1e-6)  # STL: float32
    assert load_object(tmp_path / "box.stl", units=units).symmetry == "none"


@pytest.mark.parametrize(
    ("name", "symmetry", "message"),
    [
        ("cd_drive", (1.0, 0.0, 0.0), "states its own symmetry; --symmetry"),
        ("box.stl", (0.0, 0.0, 0.1), "non-zero normal"),
        ("box.stl", (1.0, 0.0), "expected NX, NY, D"),
    ],
)
def test_a_plane_that_cannot_be_a_mesh_s_is_refused(tmp_path, name, symmetry, message):
    trimesh.creation.box((0.04, 0.06, 0.1)).export(tmp_path / "box.stl")
    target = name if name == "cd_drive" else tmp_path / name
    with pytest.raises(InputError, match=message):
        load_object(target, symmetry=symmetry)
