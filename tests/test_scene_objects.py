"""The PyBullet scene: table, object placement, mass properties, convex decomposition."""

from __future__ import annotations

import numpy as np
import pybullet
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from pipeline.errors import InputError
from pipeline.metrics import point_to_mesh_distances
from pipeline.sim import collision
from pipeline.sim import scene as scene_module
from pipeline.sim.scene import REST_SPEED_M_S, REST_SPIN_RAD_S, Scene


@pytest.fixture(autouse=True)
def private_cache(tmp_path_factory, monkeypatch):
    """Keep convex decompositions out of the user's cache directory."""
    monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path_factory.getbasetemp() / "symfuse-cache"))


def standing(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    mesh = mesh.copy()
    mesh.apply_translation(-mesh.bounds[0] * [0, 0, 1])
    return mesh


def box_mesh(size_m=(0.06, 0.1, 0.16)) -> trimesh.Trimesh:
    return standing(trimesh.creation.box(size_m))


def ring_mesh() -> trimesh.Trimesh:
    """A thick ring: non-convex, with a 60 mm hole through the middle."""
    return standing(trimesh.creation.annulus(r_min=0.03, r_max=0.05, height=0.08))


def rays_through_ring(scene: Scene) -> tuple:
    """Ray hits straight down the hole and through the wall of a ring placed at x = 0.2 m."""
    return pybullet.rayTestBatch(
        [(0.2, 0.0, 0.3), (0.24, 0.0, 0.3)],
        [(0.2, 0.0, -0.01), (0.24, 0.0, -0.01)],
        physicsClientId=scene.client,
    )


def yaw_of(quaternion_xyzw) -> float:
    return float(Rotation.from_quat(quaternion_xyzw).as_euler("xyz")[2])


@pytest.mark.parametrize("table_height_m", [0.0, 0.25])
def test_box_stands_still_at_its_planar_pose(table_height_m):
    with Scene(table_height_m=table_height_m) as scene:
        body = scene.add_object(box_mesh(), 0.4, 0.6, x_m=0.45, y_m=-0.12, yaw_rad=0.7)
        scene.step(240)
        pose = scene.object_pose(body)
    np.testing.assert_allclose(pose.position_m, [0.45, -0.12, table_height_m], atol=5e-4)
    assert yaw_of(pose.quaternion_xyzw) == pytest.approx(0.7, abs=1e-3)


@pytest.mark.parametrize("yaw_rad", [1.745, 2.79, 3.66])
def test_a_cylinder_lying_on_its_side_stays_where_it_was_put(yaw_rad):
    # A 32-sided prism on its side rests on an edge; without rolling resistance it rolled
    # off, faster and faster (120 mm in 2 s).
    lying = trimesh.creation.cylinder(radius=0.028, height=0.13)
    lying.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    with Scene() as scene:
        body = scene.add_object(standing(lying), 0.2, 0.5, yaw_rad=yaw_rad)
        start = scene.object_pose(body).position_m
        scene.step(480)
        moved_m = np.linalg.norm(scene.object_pose(body).position_m - start)
    assert moved_m < 1e-3


def test_settling_waits_until_a_toppling_object_is_still():
    # A box standing on one edge, 30 deg from upright, falls over as soon as it is placed.
    tilted = box_mesh((0.04, 0.06, 0.12))
    tilted.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 6, [1, 0, 0]))
    with Scene() as scene:
        body = scene.add_object(standing(tilted), 0.3, 0.6)
        scene.settle(body)
        linear, angular = pybullet.getBaseVelocity(body, physicsClientId=scene.client)
        fallen = scene.object_pose(body)
        scene.step(240)
        later = scene.object_pose(body)
    assert np.linalg.norm(linear) < REST_SPEED_M_S and np.linalg.norm(angular) < REST_SPIN_RAD_S
    assert np.linalg.norm(later.position_m - fallen.position_m) < 1e-3


def test_pose_is_the_mesh_frame_even_with_an_offset_centre_of_mass():
    # A box whose mesh origin is 40 mm off its centre (and centre of mass).
    offset_box = box_mesh((0.12, 0.05, 0.1))
    offset_box.apply_translation((0.04, 0.0, 0.0))
    with Scene() as scene:
        body = scene.add_object(offset_box, 0.3, 0.8, x_m=0.3, y_m=0.2, yaw_rad=-0.4)
        pose = scene.object_pose(body)
        com_world = pybullet.getBasePositionAndOrientation(body, physicsClientId=scene.client)[0]
    # Objects rest on the 0.1 mm collision margin, hence the z tolerance.
    np.testing.assert_allclose(pose.position_m, [0.3, 0.2, 0.0], atol=2e-4)
    assert yaw_of(pose.quaternion_xyzw) == pytest.approx(-0.4, abs=1e-6)
    expected_com = [0.3 + 0.04 * np.cos(-0.4), 0.2 + 0.04 * np.sin(-0.4), 0.05]
    np.testing.assert_allclose(com_world, expected_com, atol=2e-4)


def test_mass_and_inertia_of_a_uniform_box():
    a, b, c = 0.06, 0.1, 0.16
    mass = 0.5
    with Scene() as scene:
        body = scene.add_object(box_mesh((a, b, c)), mass, 0.7)
        info = pybullet.getDynamicsInfo(body, -1, physicsClientId=scene.client)
    assert info[0] == pytest.approx(mass)
    assert info[1] == pytest.approx(0.7)
    expected = sorted(
        [mass * (b**2 + c**2) / 12, mass * (a**2 + c**2) / 12, mass * (a**2 + b**2) / 12]
    )
    np.testing.assert_allclose(sorted(info[2]), expected, rtol=1e-6)
    np.testing.assert_allclose(info[3], [0.0, 0.0, c / 2], atol=1e-9)  # centre of mass


@pytest.mark.slow
def test_non_convex_mesh_keeps_its_hole_and_is_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path))  # empty: V-HACD must run here
    ring = ring_mesh()
    assert not ring.is_convex
    with Scene(vhacd_resolution=20_000) as scene:
        body = scene.add_object(ring, 0.2, 0.5, x_m=0.2)
        scene.step(120)
        # A ray straight down the hole reaches the table; one through the wall hits the ring.
        hole, wall = rays_through_ring(scene)
        assert hole[0] == scene.table_id
        assert wall[0] == body
        assert wall[3][2] == pytest.approx(0.08, abs=3e-3)
        assert scene.object_pose(body).position_m[2] == pytest.approx(0.0, abs=3e-3)
    cached = list((tmp_path / "vhacd").glob("*.obj"))
    assert len(cached) == 1
    # Shrink-wrapped: no hull vertex lies outside the true surface (trimesh: outside < 0).
    hull_vertices = trimesh.load(cached[0], force="mesh").vertices
    assert trimesh.proximity.signed_distance(ring, hull_vertices).min() > -1e-6

    def no_vhacd(*args, **kwargs):
        raise AssertionError("V-HACD ran again despite a cached decomposition")

    monkeypatch.setattr(scene_module.pybullet, "vhacd", no_vhacd)
    with Scene(vhacd_resolution=20_000) as scene:
        scene.add_object(ring_mesh(), 0.2, 0.5)


@pytest.mark.slow
def test_an_open_scan_gets_parts_on_its_surface(tmp_path, monkeypatch):
    # A scan with holes has no inside; its parts are hulls of surface samples, so the hand
    # stops on the surface the camera sees, not a voxel outside it.
    monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path))
    ring = ring_mesh()
    top = np.flatnonzero(ring.triangles_center[:, 2] > 0.079)[:6]
    scan = trimesh.Trimesh(ring.vertices, np.delete(ring.faces, top, axis=0), process=False)
    assert not scan.is_watertight and not scan.is_convex
    raw = trimesh.Trimesh(ring.vertices, ring.faces)  # the same shape, as V-HACD saw it
    path = collision.convex_decomposition(scan, 20_000)
    assert path.name.endswith("_surface.obj")
    vertices = np.vstack(collision.read_convex_parts(path))
    _, distance, _ = trimesh.proximity.closest_point(raw, vertices)
    assert distance.max() < 1e-6
    with Scene(vhacd_resolution=20_000) as scene:
        body = scene.add_object(scan, 0.2, 0.5, x_m=0.2)
        scene.step(120)
        hole, wall = rays_through_ring(scene)
        assert hole[0] == scene.table_id and wall[0] == body
        assert wall[3][2] == pytest.approx(0.08, abs=1e-3)


def test_convex_mesh_is_not_decomposed(tmp_path, monkeypatch):
    monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path))
    cylinder = standing(trimesh.creation.cylinder(radius=0.04, height=0.12))
    with Scene() as scene:
        body = scene.add_object(cylinder, 0.2, 0.5)
        hit = pybullet.rayTest((0.0, 0.0, 0.3), (0.0, 0.0, -0.01), physicsClientId=scene.client)
    assert hit[0][0] == body
    assert not (tmp_path / "vhacd").exists()


URDF = """<?xml version="1.0"?>
<robot name="block">
  <link name="base">
    <inertial><mass value="0.2"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0"
      iyz="0"/></inertial>
    <visual><geometry><box size="0.05 0.05 0.1"/></geometry></visual>
    <collision><geometry><box size="0.05 0.05 0.1"/></geometry></collision>
  </link>
</robot>
"""


def test_user_urdf_rests_on_the_table(tmp_path):
    path = tmp_path / "block.urdf"
    path.write_text(URDF)
    with Scene(table_height_m=0.1) as scene:
        body = scene.add_urdf(path, x_m=-0.2, y_m=0.3, yaw_rad=1.0)
        placed = scene.object_pose(body)
        scene.step(120)
        settled = scene.object_pose(body)
    # The block's base frame is its centre: 50 mm above the table top when resting.
    np.testing.assert_allclose(placed.position_m, [-0.2, 0.3, 0.15], atol=5e-4)
    np.testing.assert_allclose(settled.position_m, placed.position_m, atol=5e-4)
    assert yaw_of(settled.quaternion_xyzw) == pytest.approx(1.0, abs=1e-3)


def test_missing_urdf_and_bad_mass_are_input_errors(tmp_path):
    with Scene() as scene:
        with pytest.raises(InputError, match="not found"):
            scene.add_urdf(tmp_path / "nothing.urdf")
        with pytest.raises(InputError, match="mass"):
            scene.add_object(box_mesh(), 0.0, 0.5)


def test_simulation_is_deterministic_and_context_closes_client():
    def tumble():
        with Scene() as scene:
            tilted = box_mesh((0.05, 0.05, 0.2))
            body = scene.add_object(tilted, 0.3, 0.4, x_m=0.1)
            pybullet.resetBaseVelocity(
                body, [0.3, 0.1, 0.0], [0.0, 4.0, 1.0], physicsClientId=scene.client
            )
            scene.step(200)
            pose = scene.object_pose(body)
            client = scene.client
        return pose, client

    first, client = tumble()
    second, _ = tumble()
    np.testing.assert_array_equal(first.position_m, second.position_m)
    np.testing.assert_array_equal(first.quaternion_xyzw, second.quaternion_xyzw)
    assert not pybullet.isConnected(client)


def test_convex_parts_round_trip_through_obj_and_load_as_one_child_each(tmp_path):
    box = trimesh.creation.box((0.04, 0.04, 0.04))
    ball = trimesh.creation.icosphere(subdivisions=1, radius=0.02)
    ball.apply_translation((0.1, 0.0, 0.0))
    points = np.random.default_rng(0).normal(size=(30, 3)) * 0.01 + (0.0, 0.1, 0.0)
    path = tmp_path / "parts.obj"
    collision.write_convex_parts(path, [box, ball, points])
    parts = collision.read_convex_parts(path)
    expected = [box.vertices, ball.vertices, trimesh.convex.convex_hull(points).vertices]
    assert len(parts) == 3
    for part, vertices in zip(parts, expected, strict=True):
        np.testing.assert_allclose(part, vertices, atol=1e-9)
    client = pybullet.connect(pybullet.DIRECT)
    try:
        shape = pybullet.createCollisionShape(
            pybullet.GEOM_MESH, fileName=str(path), physicsClientId=client
        )
        body = pybullet.createMultiBody(0.0, shape, physicsClientId=client)
        children = pybullet.getCollisionShapeData(body, -1, physicsClientId=client)
        assert len(children) == 3
    finally:
        pybullet.disconnect(client)


def test_a_mesh_over_the_simulators_limits_is_simplified_for_it_alone(monkeypatch):
    """Over PyBullet's array limits createCollisionShape/createVisualShape fail; the mesh is
    decimated for them (here with the limits lowered, the path a 300k-face scan takes)."""
    sphere = standing(trimesh.creation.icosphere(subdivisions=4, radius=0.04))  # 5120 faces
    with Scene() as scene:
        body = scene.add_object(sphere, mass_kg=0.1, friction=0.5)
        whole = pybullet.getAABB(body, physicsClientId=scene.client)
    monkeypatch.setattr(scene_module, "MAX_CONVEX_VERTICES", 1000)
    monkeypatch.setattr(scene_module, "MAX_VISUAL_FACES", 2000)
    simple = scene_module.within_faces(sphere, 2000)
    assert len(simple.faces) <= 2000 and scene_module.within_faces(simple, 2000) is simple
    off = point_to_mesh_distances(simple.vertices, sphere.vertices, sphere.faces)
    assert off.max() < 5e-4  # the decimated surface stays on the sphere
    with Scene() as scene:
        body = scene.add_object(sphere, mass_kg=0.1, friction=0.5)
        shape = pybullet.getVisualShapeData(body, physicsClientId=scene.client)
        assert len(shape) == 1
        aabb = pybullet.getAABB(body, physicsClientId=scene.client)
        assert np.array(aabb) == pytest.approx(np.array(whole), abs=5e-4)
