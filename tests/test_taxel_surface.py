"""Taxels in contact lie on the true object surface, not on a collision hull around it.

A can whose lid is 1.5 mm wider than its body is not convex; one hull around it would
bridge the step and hold the fingers up to 1.5 mm off the body. Both hands grasp the body
below the lid, and every taxel the tactile model reports is measured against the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import trimesh

from pipeline.metrics import point_to_mesh_distances
from pipeline.types import GraspPlan
from plugins.tactile.pybullet_taxels import PybulletTaxels
from plugins.worlds.pybullet_world import Pybullet

MM = 1e-3
TOP_DOWN = np.diag([1.0, -1.0, -1.0])
#: How far the probed object surface may lie from the true one: what the collision
#: geometry is allowed to add (scene.HULL_TOLERANCE_M) plus Bullet's contact slop.
SURFACE_TOLERANCE_M = 0.3 * MM


@dataclass(frozen=True)
class _Can:
    name: str
    mesh: trimesh.Trimesh
    mass_kg: float = 0.3
    friction: float = 0.5


def _can(body_radius: float, body_height: float, lid_height: float) -> _Can:
    lid_radius = body_radius + 1.5 * MM
    top = body_height + lid_height
    profile = [
        (0.0, 0.0),
        (body_radius, 0.0),
        (body_radius, body_height),
        (lid_radius, body_height),
        (lid_radius, top),
        (0.0, top),
    ]
    mesh = trimesh.creation.revolve(np.array(profile), sections=96)
    assert mesh.is_watertight and not mesh.is_convex
    return _Can("lidded-can", mesh)


def _grasp(gripper: str, can: _Can, palm_z: float, opening: float, spread: float):
    with Pybullet.create(can, gripper, 0.5, 0.0) as world:
        T = np.eye(4)
        T[:3, :3] = TOP_DOWN
        T[:3, 3] = [0.5, 0.0, palm_z]
        closing = np.array([1.0, 0.0, 0.0])
        plan = GraspPlan(gripper, "ok", T, 0.06, opening, closing, spread_rad=spread)
        outcome = world.execute_grasp(plan)
        assert outcome.executed, outcome.reason
        taxels = PybulletTaxels()
        contacts = taxels.read(world, outcome)
        frames, gaps = world.sim.hand.taxel_gaps(
            world.sim.object_id, taxels.params.ray_behind_m, taxels.params.ray_length_m
        )
        # Rays that start inside the object (pressed in) measure nothing but the press.
        touching = (gaps <= taxels.params.contact_threshold_m) & (
            gaps > -taxels.params.ray_behind_m
        )
        probed = frames.positions[touching] + gaps[touching, None] * frames.normals[touching]
        mesh = can.mesh.copy()
        mesh.apply_transform(world.object_pose().transform)
        surface = point_to_mesh_distances(probed, mesh.vertices, mesh.faces)
        taxel = point_to_mesh_distances(contacts.positions, mesh.vertices, mesh.faces)
        return contacts, surface, taxel, taxels.params.contact_threshold_m


@pytest.fixture(autouse=True)
def _fresh_decomposition_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SYMFUSE_CACHE", str(tmp_path))


@pytest.mark.parametrize(
    ("gripper", "body_radius", "palm_z", "opening", "spread"),
    [
        # Distal pad centres about 215 mm below the palm once closed: 75 mm up the body.
        ("sdh", 45 * MM, 0.29, 0.125, np.deg2rad(60.0)),
        # Pad centres 125 mm below the palm: 70 mm up the body, the housing above the lid.
        ("pg70", 20 * MM, 0.195, 0.065, 0.0),
    ],
)
def test_taxels_in_contact_lie_on_the_true_surface(gripper, body_radius, palm_z, opening, spread):
    can = _can(body_radius, 100 * MM, 10 * MM)
    contacts, surface, taxel, threshold = _grasp(gripper, can, palm_z, opening, spread)
    assert len(np.unique(contacts.pads)) >= (3 if gripper == "sdh" else 2)
    # Where the rays of the touching taxels meet the object is the true surface ...
    assert np.all(surface <= SURFACE_TOLERANCE_M), np.sort(surface)[-5:] / MM
    # ... so a reported taxel is off it by no more than its own gap.
    assert np.all(taxel <= threshold + SURFACE_TOLERANCE_M), np.sort(taxel)[-5:] / MM
