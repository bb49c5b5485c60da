"""The SDH-2's whole finger in the closing check (its distal link above and below its pad)
and the pinch across an open object's wall at its rim (:mod:`pipeline.planning.rim`)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from pipeline.config import load_config
from pipeline.metrics.evaluation import opposing_contacts
from pipeline.planning.hand_choice import choose_grasp
from pipeline.planning.rim import RIM_WALL_M, RimSite, find_rim, rim_sites, ring_centre
from pipeline.planning.sdh_candidates import SdhHand
from pipeline.planning.sdh_geometry import DISTAL_PAD_CURVE_RADIUS_M
from pipeline.registry import load_registry
from pipeline.sim.hand_models import GRIPPERS, SDH
from plugins.worlds.pybullet_world import Pybullet

TOLERANCE_M = 0.003


@pytest.fixture(scope="module")
def distal_pad():
    return SdhHand.of(GRIPPERS["sdh"], "test").distal_pad_m()


def _at_distal(down_m: float, forward_m: float, alpha_rad: float) -> tuple[float, float]:
    """(t, depth) of a point ``down_m`` below the distal joint and ``forward_m`` ahead of
    the distal link's axis, the proximal link at ``alpha_rad``."""
    t = SDH.proximal_length_m * math.sin(alpha_rad) + forward_m
    depth = SDH.knuckle_depth_m + SDH.proximal_length_m * math.cos(alpha_rad) + down_m
    return t, depth


def test_the_distal_pad_is_where_the_urdf_puts_it(distal_pad):
    """13 rows of 3.4 mm centred 42 mm from the distal joint, the 9 nearest the tip
    curved with radius 59 mm: the flat part's 4 rows end 8.5 mm above the centre; the last
    row's centre lies 28.9 mm along the curve from there, 59 sin(28.9 / 59) = 27.75 mm
    down, and its cell half a pitch (1.7 mm) below that."""
    (top, bottom), curve_start = distal_pad
    assert top == pytest.approx(0.042 - 0.0221)
    assert curve_start == pytest.approx(0.042 - 0.0085)
    last = 0.059 * math.sin(0.0289 / 0.059)
    assert bottom == pytest.approx(curve_start + last + 0.0017, abs=1e-6)


@pytest.mark.parametrize("alpha_deg", [-20.0, 0.0, 15.0])
def test_the_distal_link_is_hit_below_and_above_its_pad_but_not_at_it(distal_pad, alpha_deg):
    """Hand-computed: at the tip (68.5 mm below the joint, 35 mm along the curve from
    33.5 mm) the pad's surface lies 59 - sqrt(59^2 - 35^2) = 11.50 mm behind its flat
    front (14.8 mm ahead of the axis); a point 1 mm behind that front, beyond the touch
    tolerance, is in the link, 1 mm in front of it is not. At the pad's rows the pad's
    predicted contact decides, so even a point deep inside is not counted there."""
    rows, curve_start = distal_pad
    alpha = math.radians(alpha_deg)
    tip = SDH.distal_length_m
    recess = DISTAL_PAD_CURVE_RADIUS_M - math.sqrt(DISTAL_PAD_CURVE_RADIUS_M**2 - 0.035**2)
    assert recess == pytest.approx(0.01150, abs=1e-5)
    front_at_tip = SDH.distal_pad_offset_m - recess
    cases = {
        # (down, forward): inside?
        (tip - 0.0005, front_at_tip - TOLERANCE_M - 0.001): True,
        (tip - 0.0005, front_at_tip - TOLERANCE_M + 0.001): False,
        (tip + TOLERANCE_M + 0.001, 0.0): False,  # below the tip
        (0.005, SDH.distal_pad_offset_m - TOLERANCE_M - 0.001): True,  # above the pad
        (0.005, SDH.distal_pad_offset_m + 0.001): False,
        (0.005, SDH.distal_back_m - TOLERANCE_M - 0.001): False,  # behind the link's back
        (0.042, 0.0): False,  # at the pad's rows: the pad's contact decides
    }
    points = np.array([_at_distal(d, f, alpha) for d, f in cases])
    hits = SDH.distal_hits(
        points[:, 0], points[:, 1], [alpha], TOLERANCE_M, rows, curve_start, TOLERANCE_M
    )
    assert hits.shape == (1, len(cases))
    assert hits[0].tolist() == list(cases.values())


def _bowl_view(
    radius_m: float, height_m: float, viewpoint: np.ndarray, open_top: bool = True
) -> np.ndarray:
    """What a camera at ``viewpoint`` sees of a thin-walled open cylinder (or, not
    ``open_top``, a closed one) standing on z = 0 at the origin: the faces turned to it,
    sampled every 2 mm, the near wall hiding the inside behind it."""
    if open_top:
        profile = [(0, 0), (radius_m, 0), (radius_m, height_m), (radius_m - 0.003, height_m)]
        profile += [(radius_m - 0.003, 0.003), (0, 0.003)]
    else:
        profile = [(0, 0), (radius_m, 0), (radius_m, height_m), (0, height_m)]
    mesh = trimesh.creation.revolve(np.array(profile), sections=96)
    samples, faces = trimesh.sample.sample_surface_even(mesh, 20000, radius=0.002, seed=3)
    towards = viewpoint - samples
    facing = np.einsum("ij,ij->i", mesh.face_normals[faces], towards) > 0.0
    samples = samples[facing]
    rays = viewpoint - samples
    distance = np.linalg.norm(rays, axis=1)
    origins = samples + rays / distance[:, None] * 1e-4
    hit = mesh.ray.intersects_any(origins, rays / distance[:, None])
    return samples[~hit]


VIEWPOINT = np.array([-0.7, 0.0, 0.75])


def test_an_open_top_has_rim_sites_on_its_far_side_and_a_closed_top_none():
    seen = _bowl_view(0.075, 0.06, VIEWPOINT)
    sites = rim_sites(find_rim(seen), 12, VIEWPOINT)
    assert 3 <= len(sites) <= 6
    for site in sites:
        assert isinstance(site, RimSite)
        # Beyond the centre from the camera: the camera sees the inner face there.
        assert site.outward[:2] @ (site.centre_m[:2] - VIEWPOINT[:2]) > 0.0
        assert site.radius_m == pytest.approx(0.0735, abs=0.003)
        assert np.hypot(*site.wall_m[:2]) == pytest.approx(0.0735, abs=0.004)
        assert site.wall_m[2] == pytest.approx(0.06, abs=0.003)
    assert find_rim(_bowl_view(0.075, 0.06, VIEWPOINT, open_top=False)) is None
    assert rim_sites(find_rim(seen), 12, None) == []


def test_ring_centre_finds_a_circle_from_part_of_its_turn():
    """Points on a third of a circle (centre (0.6, 0.1), radius 70 mm): the fit is the
    circle, where their mean is not."""
    turn = np.linspace(0.0, 2.0 * math.pi / 3.0, 40)
    points = np.column_stack([0.6 + 0.07 * np.cos(turn), 0.1 + 0.07 * np.sin(turn)])
    centre, radius = ring_centre(points)
    np.testing.assert_allclose(centre, [0.6, 0.1], atol=1e-9)
    assert radius == pytest.approx(0.07, abs=1e-9)


def test_a_pad_beside_the_closing_line_may_stop_where_the_rim_curves_away():
    """Fingers 1 and 2 stand 33 mm to either side of the line through the site: the rim
    (radius 75 mm) lies 75 - sqrt(75^2 - 33^2) = 7.65 mm further along it there."""
    site = RimSite(np.array([0.075, 0.0, 0.06]), np.array([1.0, 0.0, 0.0]), np.zeros(3), 0.075)
    assert site.beyond_m(0.033) == pytest.approx(0.07500 - 0.06735 + RIM_WALL_M, abs=1e-5)
    assert site.beyond_m(0.0) == pytest.approx(RIM_WALL_M)


def _bowl(name: str) -> SimpleNamespace:
    """A bowl 150 mm wide and 55 mm tall, its 3 mm wall a quarter ellipse from a 60 mm
    foot, vertical at the rim (a revolved profile, watertight)."""
    radius, height, wall, foot = 0.075, 0.055, 0.003, 0.030
    z = np.linspace(0.0, height, 24)
    outer = foot + (radius - foot) * np.sqrt(1.0 - (1.0 - z / height) ** 2)
    z_in = np.linspace(height, wall, 24)
    inner = foot + (radius - foot) * np.sqrt(np.clip(1.0 - (1.0 - z_in / height) ** 2, 0.0, 1.0))
    profile = [
        (0.0, 0.0),
        *zip(outer, z, strict=True),
        *zip(np.maximum(inner - wall, 0.0), z_in, strict=True),
        (0.0, wall),
    ]
    mesh = trimesh.creation.revolve(np.array(profile), sections=128)
    return SimpleNamespace(name=name, mesh=mesh, mass_kg=0.3, friction=0.6)


@pytest.mark.slow
def test_a_bowl_150_mm_wide_is_pinched_at_its_rim_from_opposing_sides():
    """No hand closes around the bowl (the PG-70 is too narrow, the SDH-2's fingers
    cannot descend around its rim's fitted circle and meet its receding wall with their
    pads): the SDH-2 pinches the wall at the rim, the thumb inside, and its first grasp
    has taxels on both faces."""
    registry = load_registry()
    bowl = _bowl("bowl")
    config = load_config(registry, overrides=["trial.gripper=auto", "trial.seed=32"])
    stages = {s: config.create(registry, s) for s in ("sensor", "segmenter", "initialiser")}
    with Pybullet.create(bowl, None, yaw=math.radians(40.0), seed=32) as world:
        observation = stages["sensor"].observe(world)
        cloud = stages["segmenter"].segment(observation)
        assert find_rim(cloud.points) is not None
        proposal = stages["initialiser"].propose(cloud, observation)
        choice = choose_grasp(
            config, registry, cloud, proposal, GRIPPERS, observation.table_height_m
        )
        plan = choice.plan
        assert plan.status == "ok", plan.reason
        assert plan.gripper == "sdh" and plan.spread_rad == 0.0
        # The thumb (the closing direction's origin side) inside the opening.
        assert np.hypot(*plan.predicted_contacts[:, :2].mean(axis=0)) > 0.05
        world.add_hand(plan.gripper)
        outcome = world.execute_grasp(plan)
        assert outcome.executed, outcome.reason
        contacts = config.create(registry, "tactile").read(world, outcome)
    assert opposing_contacts(contacts)
    assert any(pad.startswith("thumb") for pad in contacts.pads)
