"""The volume a view leaves hidden under the seen cloud (:func:`hidden_below`), checked
against the true objects a pinhole camera rendered here (trimesh's ray casting): every
hidden point lies inside the object, a box seen end-on is filled out to its full length,
and the space the camera saw under an overhang stays empty; with it, a hand grasps a box
seen end-on by its long sides (:func:`choose_grasp`), which no hand finds without it."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pipeline.config import load_config
from pipeline.planning.hand_choice import choose_grasp
from pipeline.planning.hidden_volume import hidden_below
from pipeline.registry import load_registry
from pipeline.sim.hands import GRIPPERS
from pipeline.synthetic import box_object, synthetic_observation
from pipeline.types import Bias, SymmetryInit, SymmetryPlane
from plugins.segmenters.table_cluster import TableCluster

# Ray casting takes about a second: the default suite has no room for it.
pytestmark = pytest.mark.slow

VIEWPOINT = np.array([-0.7, 0.0, 0.75])


def _seen(mesh: trimesh.Trimesh, rays: int = 70) -> np.ndarray:
    """The first surface points of ``mesh`` hit by ``rays`` x ``rays`` rays from
    :data:`VIEWPOINT`, spread over the mesh's bounding box."""
    low, high = mesh.bounds
    u, v = np.meshgrid(np.linspace(low[1], high[1], rays), np.linspace(low[2], high[2], rays))
    # Aim at a vertical sheet through the box's centre: covers the object's silhouette.
    targets = np.column_stack([np.zeros(u.size), u.ravel(), v.ravel()])
    targets = np.concatenate([targets + np.array([x, 0.0, 0.0]) for x in (0.0, low[0], high[0])])
    directions = targets - VIEWPOINT
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    origins = np.repeat(VIEWPOINT[None], len(directions), axis=0)
    hits, _, _ = mesh.ray.intersects_location(origins, directions, multiple_hits=False)
    return hits


def _behind_surface(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Whether the ray from :data:`VIEWPOINT` to each of ``points`` meets ``mesh`` first."""
    directions = points - VIEWPOINT
    ranges = np.linalg.norm(directions, axis=1)
    origins = np.repeat(VIEWPOINT[None], len(points), axis=0)
    hits, ray, _ = mesh.ray.intersects_location(
        origins, directions / ranges[:, None], multiple_hits=False
    )
    first = np.full(len(points), np.inf)
    first[ray] = np.linalg.norm(hits - VIEWPOINT, axis=1)
    return first < ranges


def test_a_box_seen_end_on_is_filled_to_its_length_and_nowhere_else():
    # 65 mm thick along y, 130 mm long along x (away from the camera), 170 mm tall.
    box = trimesh.creation.box((0.13, 0.065, 0.17))
    box.apply_translation([0.0, 0.0, 0.085])
    seen = _seen(box)
    mid = np.abs(seen[:, 2] - 0.08) < 0.005
    assert np.ptp(seen[mid, 0]) < 0.01  # at mid-height the camera sees the end face only
    hidden = hidden_below(seen, VIEWPOINT, 0.004)
    assert len(hidden)
    assert np.all(np.abs(hidden[:, :2]) <= [0.065 + 1e-6, 0.0325 + 1e-6])
    assert hidden[:, 2].min() >= -1e-6 and hidden[:, 2].max() <= 0.17
    band = hidden[np.abs(hidden[:, 2] - 0.08) < 0.003]
    assert np.ptp(band[:, 0]) > 0.12 and np.ptp(band[:, 1]) > 0.055


def test_the_space_seen_under_an_overhang_stays_empty():
    # A cap 120 mm wide on a stem 30 mm wide: the camera, 47 deg above the table, sees the
    # stem's lower part under the cap's near side, so the space in front of it is free;
    # close under the cap and behind the stem it could not see.
    stem = trimesh.creation.box((0.03, 0.03, 0.1))
    stem.apply_translation([0.0, 0.0, 0.05])
    cap = trimesh.creation.box((0.12, 0.12, 0.02))
    cap.apply_translation([0.0, 0.0, 0.11])
    mushroom = trimesh.util.concatenate([stem, cap])
    hidden = hidden_below(_seen(mushroom), VIEWPOINT, 0.004)
    # Hidden points are out of the camera's sight (a ray to each meets the object first)
    # but for some on the edge of the cap's shadow, within the rays' width of it: 6 mm
    # higher, under the cap, each is out of sight.
    in_sight = ~_behind_surface(mushroom, hidden)
    assert np.count_nonzero(in_sight) < 0.05 * len(hidden)
    assert np.all(_behind_surface(mushroom, hidden[in_sight] + [0.0, 0.0, 0.006]))
    in_front = (hidden[:, 0] < -0.015 - 0.004) & (hidden[:, 2] < 0.05)
    assert not np.any(in_front)  # seen free space
    assert np.any((hidden[:, 0] > 0.015) & (hidden[:, 2] < 0.05))  # behind the stem: kept


def test_a_box_seen_end_on_is_grasped_by_its_sides_only_with_the_hidden_volume(monkeypatch):
    import pipeline.planning.hand_choice as hand_choice

    # 130 mm long away from the camera, 65 mm thick across, mirror plane across its
    # thickness: the plane's mirror image of the seen end face is that face again.
    registry = load_registry()
    config = load_config(registry)
    box = box_object(0.13, 0.065, 0.17)
    observation = synthetic_observation(box, (0.6, 0.0, 0.0), rng=np.random.default_rng(8))
    cloud = TableCluster().segment(observation)
    proposal = SymmetryInit(SymmetryPlane(np.pi / 2.0, 0.0), Bias())
    choice = choose_grasp(config, registry, cloud, proposal, GRIPPERS, 0.0)
    assert choice.plan.status == "ok" and choice.reason.endswith("hidden under the cloud")
    # The pads meet the two long faces (y = +-32.5 mm), within the box's length, where the
    # hidden points stand on a 4 mm grid.
    contacts = choice.plan.predicted_contacts
    assert np.all(np.abs(np.abs(contacts[:, 1]) - 0.0325) < 0.008)  # two grid steps
    assert contacts[:, 1].min() < 0.0 < contacts[:, 1].max()
    assert np.all(np.abs(contacts[:, 0] - 0.6) < 0.065)
    # Without it no hand finds a side to close on.
    monkeypatch.setattr(hand_choice, "_with_hidden_volume", lambda cloud: None)
    refused = choose_grasp(config, registry, cloud, proposal, GRIPPERS, 0.0)
    assert refused.plan.status == "refused"
