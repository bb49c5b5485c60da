"""Symmetry as a type, the mesh symmetry search, its scoring and ``symmetry.json``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh

from pipeline.catalogue.objects import list_objects, load_object
from pipeline.errors import InputError
from pipeline.metrics.evaluation import plane_errors
from pipeline.symmetry.scoring import symmetry_errors
from pipeline.symmetry.search import SearchSettings, mesh_symmetries
from pipeline.symmetry.truth_file import read_symmetries, symmetries_to_json
from pipeline.types import Symmetry, SymmetryPlane

#: A quicker search than the default, enough for the simple solids below.
QUICK = SearchSettings(samples=250, reference_samples=4000, directions=120, refined=3)


def unit(*vector: float) -> np.ndarray:
    return np.array(vector) / np.linalg.norm(vector)


def test_mirror_and_turn_match_hand_computed_points():
    plane = Symmetry("plane", [0.0, 0.0, 2.0], [5.0, 5.0, 1.0])
    assert np.allclose(plane.apply(np.array([[1.0, 2.0, 3.0]])), [[1.0, 2.0, -1.0]])
    axis = Symmetry("axis", [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    turned = axis.apply(np.array([[2.0, 0.0, 7.0]]), math.pi / 2)
    assert np.allclose(turned, [[1.0, 1.0, 7.0]])


def test_vertical_plane_is_the_papers_plane_and_its_parameters():
    plane = SymmetryPlane(theta_rad=0.3, offset_m=0.05)
    symmetry = Symmetry.from_plane(plane, covariance=np.diag([1e-6, 1e-4]))
    points = np.random.default_rng(0).normal(size=(20, 3))
    assert symmetry.kind == "vertical-plane"
    assert np.allclose(symmetry.apply(points), plane.mirror(points))
    assert np.allclose(symmetry.values, [0.05, 0.3])
    assert symmetry.parameters == ("m_r", "m_theta")


def test_a_tilted_vertical_plane_becomes_a_general_one():
    T = trimesh.transformations.rotation_matrix(math.pi / 2, [1.0, 0.0, 0.0])
    vertical = Symmetry.from_plane(SymmetryPlane(math.pi / 2, 0.0))
    assert vertical.transformed(T).kind == "plane"
    assert Symmetry.from_plane(SymmetryPlane(0.0, 0.0)).transformed(T).kind == "vertical-plane"


def test_axis_parameters_locate_its_point_across_the_direction():
    axis = Symmetry("axis", [0.0, 0.0, -1.0], [0.02, -0.01, 0.3])
    _, elevation, u, v = axis.values
    assert elevation == pytest.approx(math.pi / 2)
    across_u, across_v = axis.across_axes()
    assert np.allclose(u * across_u + v * across_v, [0.02, -0.01, 0.0])


def test_search_finds_a_boxs_three_planes_and_no_axis():
    box = trimesh.creation.box(extents=[0.04, 0.10, 0.16])
    found = mesh_symmetries(box.vertices, box.faces, QUICK)
    normals = sorted(
        int(np.argmax(np.abs(s.direction))) for s in found.symmetries if s.kind == "plane"
    )
    assert found.kind == "plane" and normals == [0, 1, 2]
    assert all(np.abs(s.direction).max() > math.cos(math.radians(2.0)) for s in found.symmetries)


def test_search_finds_a_tilted_cylinders_axis():
    direction = unit(1.0, 0.5, 2.0)
    cylinder = trimesh.creation.cylinder(radius=0.03, height=0.12, sections=64)
    cylinder.apply_transform(trimesh.geometry.align_vectors([0.0, 0.0, 1.0], direction))
    cylinder.apply_translation([0.1, -0.2, 0.05])
    found = mesh_symmetries(cylinder.vertices, cylinder.faces, QUICK)
    axes = [s for s in found.symmetries if s.kind == "axis"]
    assert len(axes) == 1
    assert math.degrees(math.acos(abs(axes[0].direction @ direction))) < 2.0
    offset = axes[0].point_m - np.array([0.1, -0.2, 0.05])
    assert np.linalg.norm(offset - (offset @ direction) * direction) < 0.001
    # The plane across the middle remains; the planes through the axis follow from it.
    assert [s.kind for s in found.symmetries].count("plane") == 1


def test_a_handle_breaks_the_axis_but_keeps_the_plane():
    body = trimesh.creation.cylinder(radius=0.04, height=0.10, sections=64)
    handle = trimesh.creation.box(extents=[0.03, 0.012, 0.06])
    handle.apply_translation([0.05, 0.0, 0.0])
    mug = trimesh.util.concatenate([body, handle])
    found = mesh_symmetries(mug.vertices, mug.faces, QUICK)
    assert "axis" not in [s.kind for s in found.symmetries]
    vertical = [s for s in found.symmetries if abs(s.direction[2]) < 0.1]
    assert len(vertical) == 1 and abs(vertical[0].direction[1]) > math.cos(math.radians(2.0))


@pytest.mark.slow
def test_search_agrees_with_the_catalogues_hand_written_symmetry():
    """Every catalogue object: a planar one has its stated plane among the planes found, a
    rotational one a vertical axis (the catalogue's table is written by hand)."""
    for info in list_objects():
        obj = load_object(info.name)
        found = mesh_symmetries(obj.mesh.vertices, obj.mesh.faces)
        if info.symmetry == "rotational":
            assert any(s.kind == "axis" and abs(s.direction[2]) > 0.999 for s in found.symmetries)
        elif info.symmetry == "planar":
            assert "axis" not in [s.kind for s in found.symmetries], info.name
            truth = Symmetry.from_plane(info.symmetry_plane)
            errors = symmetry_errors(truth, found.symmetries, obj.mesh.bounds.mean(axis=0))
            assert errors["symmetry_angle_error_deg"] < 1.0, info.name
            assert errors["symmetry_offset_error_mm"] < 1.0, info.name


def test_scoring_against_hand_computed_angles_and_offsets():
    centre = np.array([0.0, 0.0, 0.05])
    tilted = Symmetry("plane", unit(1.0, 0.0, math.tan(math.radians(10.0))), [0.002, 0.0, 0.0])
    truth_plane = Symmetry("plane", [1.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    errors = symmetry_errors(tilted, [truth_plane], centre)
    assert errors["symmetry_angle_error_deg"] == pytest.approx(10.0)
    # The true plane's point nearest the centre is (0, 0, 0.05): its distance to the tilted plane.
    expected = abs(tilted.direction @ (np.array([0.0, 0.0, 0.05]) - tilted.point_m)) * 1e3
    assert errors["symmetry_offset_error_mm"] == pytest.approx(expected)
    # A plane is a symmetry of a body of revolution when it contains the axis.
    axis = Symmetry("axis", [0.0, 0.0, 1.0], [0.003, 0.0, 0.0])
    errors = symmetry_errors(Symmetry("plane", [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]), [axis], centre)
    assert errors["symmetry_angle_error_deg"] == pytest.approx(0.0)
    assert errors["symmetry_offset_error_mm"] == pytest.approx(0.0)
    assert errors["symmetry_truth_kind"] == "axis"
    # An axis is not scored against a plane.
    assert symmetry_errors(axis, [truth_plane], centre) == {}
    # The nearest of several truths counts.
    errors = symmetry_errors(
        Symmetry("plane", [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]),
        [truth_plane, Symmetry("plane", unit(0.0, 1.0, 0.1), [0.0, 0.0, 0.0])],
        centre,
    )
    assert errors["symmetry_angle_error_deg"] == pytest.approx(math.degrees(math.atan(0.1)))


def test_vertical_scoring_agrees_with_the_papers_plane_errors():
    from pipeline.metrics.evaluation import GroundTruth

    true_plane = SymmetryPlane.from_normal(np.array([1.0, 0.2]), 0.01)
    estimate = SymmetryPlane(0.5, 0.03)
    truth = GroundTruth(
        vertices=np.zeros((1, 3)),
        faces=np.zeros((0, 3), dtype=int),
        symmetry="planar",
        plane=true_plane,
        axis_xy_m=true_plane.normal[:2] * true_plane.offset_m,
    )
    paper = plane_errors(estimate, truth)
    ours = symmetry_errors(
        Symmetry.from_plane(estimate),
        [Symmetry.from_plane(true_plane)],
        np.append(truth.axis_xy_m, 0.0),
    )
    assert ours["symmetry_angle_error_deg"] == pytest.approx(paper["plane_angle_error_deg"])
    assert ours["symmetry_offset_error_mm"] == pytest.approx(paper["plane_offset_error_mm"])


def test_symmetry_json_beside_a_mesh_is_read_in_the_object_frame(tmp_path):
    box = trimesh.creation.box(extents=[40.0, 100.0, 160.0])
    box.apply_translation([1000.0, 0.0, 80.0])  # millimetres, off the origin
    box.export(tmp_path / "box.obj")
    stated = [Symmetry("plane", [1.0, 0.0, 0.0], [1000.0, 0.0, 0.0])]
    document = symmetries_to_json(stated, "box.obj")
    document["units"] = "mm"
    (tmp_path / "symmetry.json").write_text(json.dumps(document))
    obj = load_object(tmp_path / "box.obj", units="mm")
    assert len(obj.symmetries) == 1
    assert np.allclose(obj.symmetries[0].direction, [1.0, 0.0, 0.0])
    assert obj.symmetries[0].offset_m == pytest.approx(0.0, abs=1e-9)
    # The level plane is the paper's plane too: the trial's plane errors score it.
    assert obj.symmetry == "planar" and obj.symmetry_plane.offset_m == pytest.approx(0.0)


def test_symmetry_json_of_another_mesh_does_not_apply(tmp_path):
    trimesh.creation.box(extents=[0.04, 0.1, 0.16]).export(tmp_path / "box.obj")
    stated = [Symmetry("plane", [1.0, 0.0, 0.0], [0.0, 0.0, 0.0])]
    (tmp_path / "symmetry.json").write_text(json.dumps(symmetries_to_json(stated, "other.obj")))
    assert load_object(tmp_path / "box.obj").symmetries == ()


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"kind": "cone"}, "symmetries[0].kind must be 'plane' or 'axis'"),
        ({"kind": "plane", "normal": [0, 0, 0], "point": [0, 0, 0]}, "normal must not be zero"),
        ({"kind": "axis", "direction": [0, 0], "point": [0, 0, 0]}, "direction must be three"),
        (
            {"kind": "plane", "normal": [1, 0, 0], "point": [0, 0, 0], "offset": 1},
            "'symmetries[0].offset'",
        ),
    ],
)
def test_bad_symmetry_json_names_the_file_and_the_entry(tmp_path, entry, message):
    path = tmp_path / "symmetry.json"
    path.write_text(json.dumps({"mesh": "m.obj", "symmetries": [entry]}))
    with pytest.raises(InputError, match=f"{path}: .*") as raised:
        read_symmetries(path)
    assert message in str(raised.value)


def test_searched_symmetries_are_kept_in_the_cache(tmp_path, monkeypatch):
    from pipeline.symmetry import search, truth_file

    monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path))
    box = trimesh.creation.box(extents=[0.04, 0.10, 0.16])
    monkeypatch.setattr(search, "mesh_symmetries", lambda v, f: mesh_symmetries(v, f, QUICK))
    first = truth_file.searched_symmetries(box.vertices, box.faces)
    assert len(list((tmp_path / "symmetry").glob("*.json"))) == 1

    def refuse(*_):
        raise AssertionError("searched again")

    monkeypatch.setattr(search, "mesh_symmetries", refuse)
    again = truth_file.searched_symmetries(box.vertices, box.faces)
    assert [s.kind for s in again] == [s.kind for s in first]
    assert all(np.allclose(a.direction, b.direction) for a, b in zip(again, first, strict=True))


def test_a_sphere_is_symmetric_about_every_axis_and_plane_through_its_centre():
    centre = np.array([0.1, 0.0, 0.05])
    truths = [Symmetry("axis", [1.0, 0.0, 0.0], centre), Symmetry("axis", [0.0, 1.0, 0.0], centre)]
    tilted = Symmetry("axis", unit(1.0, 2.0, 3.0), centre + np.array([0.0, 0.0, 0.002]))
    errors = symmetry_errors(tilted, truths, centre)
    assert errors["symmetry_angle_error_deg"] == pytest.approx(0.0, abs=1e-6)
    offset = np.linalg.norm(np.cross([0.0, 0.0, 0.002], tilted.direction)) * 1e3
    assert errors["symmetry_offset_error_mm"] == pytest.approx(offset)
    plane = Symmetry("plane", unit(0.0, 1.0, 1.0), centre)
    assert symmetry_errors(plane, truths, centre)["symmetry_angle_error_deg"] == pytest.approx(0.0)


def test_plane_parameters_name_the_plane_whichever_the_normals_sign():
    normal = unit(1.0, 1.0, -math.sqrt(2.0))  # 45 deg below the table, azimuth 45 deg
    plane = Symmetry("plane", normal, 0.1 * normal)
    flipped = Symmetry("plane", -normal, 0.1 * normal)
    offset, azimuth, elevation = plane.values
    assert offset == pytest.approx(-0.1)
    assert math.degrees(azimuth) == pytest.approx(-135.0)
    assert math.degrees(elevation) == pytest.approx(45.0)
    assert np.allclose(flipped.values, plane.values)


def test_the_catalogue_ships_the_search_for_every_object(tmp_path, monkeypatch):
    """Every catalogue mesh's searched symmetries ship in ``objects/symmetry/`` under its
    digest, so no trial searches a catalogue object: a changed mesh or search version must
    ship them again (docs/symmetry.md says how)."""
    from objects import ROOT
    from pipeline.sim.collision import mesh_hash
    from pipeline.symmetry.search import SEARCH_VERSION
    from pipeline.symmetry.truth_file import true_symmetries

    monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path / "cache"))
    for info in list_objects():
        obj = load_object(info.name)
        digest = mesh_hash(trimesh.Trimesh(obj.mesh.vertices, obj.mesh.faces, process=False))
        shipped = ROOT / "symmetry" / f"{digest}-v{SEARCH_VERSION}.json"
        assert shipped.is_file(), f"{info.name}: no shipped symmetries"
        found, expected = true_symmetries(obj), read_symmetries(shipped)[0]
        assert len(found) == len(expected)
        for a, b in zip(found, expected, strict=True):
            assert a.kind == b.kind
            assert np.allclose(a.direction, b.direction) and np.allclose(a.point_m, b.point_m)
    assert not (tmp_path / "cache").exists()  # nothing was searched
