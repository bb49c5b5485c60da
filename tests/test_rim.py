"""The SDH-2's whole finger in the closing check (its distal link above and below its pad)
and the pinch across an open object's wall at its rim (:mod:`pipeline.planning.rim`)."""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from pipeline.config import load_config
from pipeline.metrics.evaluation import opposing_contacts
from pipeline.planning.candidate import Candidate
from pipeline.planning.grasp_candidates import plan_from_candidates
from pipeline.planning.hand_choice import choose_grasp
from pipeline.planning.hidden_volume import hidden_below, seen_surface
from pipeline.planning.rim import (
    RIM_WALL_M,
    WALL_LEANS,
    Rim,
    RimSite,
    find_rim,
    lean_limit_rad,
    lean_named,
    off_leaning_wall,
    rim_sites,
    ring_centre,
)
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
    radius_m: float,
    height_m: float,
    viewpoint: np.ndarray,
    open_top: bool = True,
    lean_deg: float = 0.0,
) -> np.ndarray:
    """What a camera at ``viewpoint`` sees of a thin-walled open cone, its 3 mm wall
    ``lean_deg`` from vertical, the rim ``radius_m`` wide (a cylinder at 0; not
    ``open_top``, a closed cylinder), standing on z = 0 at the origin: the faces turned
    to it, sampled every 2 mm, the near wall hiding the inside behind it."""
    foot = radius_m - height_m * math.tan(math.radians(lean_deg))
    if open_top:
        profile = [(0, 0), (foot, 0), (radius_m, height_m), (radius_m - 0.003, height_m)]
        profile += [(foot - 0.003, 0.003), (0, 0.003)]
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


def test_a_top_spread_wider_than_a_wall_is_no_rim():
    """The top of a rounded body fits a circle around lower points as a rim does, but
    spreads across it: a bowl's top points moved in and out by 10 mm (std) are no rim."""
    seen = _bowl_view(0.075, 0.06, VIEWPOINT)
    assert find_rim(seen) is not None
    top = seen[:, 2] > 0.06 - 0.01
    spread = seen.copy()
    scale = 1.0 + np.random.default_rng(0).normal(0.0, 0.010 / 0.075, np.count_nonzero(top))
    spread[top, :2] *= scale[:, None]
    assert find_rim(spread) is None


@pytest.mark.parametrize("lean_deg", [0.0, 15.0, 30.0, 60.0])
def test_a_walls_lean_is_measured_on_its_seen_inner_face(lean_deg):
    """Cones 150 mm wide at the rim and 40 mm tall, their walls leaning 0-60 deg: at
    every site (the far side, where the inner face is seen) the measured lean is the
    cone's within 4 deg."""
    seen = _bowl_view(0.075, 0.04, VIEWPOINT, lean_deg=lean_deg)
    sites = rim_sites(find_rim(seen), 12, VIEWPOINT)
    assert sites
    for site in sites:
        lean = site.lean_rad(seen, 0.04)
        assert lean is not None
        assert math.degrees(lean) == pytest.approx(lean_deg, abs=4.0)


def _rendered_cone(radius_m: float, height_m: float, lean_deg: float) -> np.ndarray:
    """What a depth camera at :data:`VIEWPOINT` sees of an open cone (as
    :func:`_bowl_view`): the first hits of rays on a grid 1.4 mrad apart (a Kinect's
    pixels), aimed over the cone's bounding box."""
    foot = radius_m - height_m * math.tan(math.radians(lean_deg))
    profile = [(0, 0), (foot, 0), (radius_m, height_m), (radius_m - 0.003, height_m)]
    profile += [(foot - 0.003, 0.003), (0, 0.003)]
    mesh = trimesh.creation.revolve(np.array(profile), sections=96)
    centre = mesh.bounds.mean(axis=0)
    axis = (centre - VIEWPOINT) / np.linalg.norm(centre - VIEWPOINT)
    right = np.cross(axis, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, axis)
    span = np.arange(-0.13, 0.13, 0.0014)
    u, v = np.meshgrid(span, span)
    directions = axis + u.reshape(-1, 1) * right + v.reshape(-1, 1) * up
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    origins = np.repeat(VIEWPOINT[None], len(directions), axis=0)
    hits, _, _ = mesh.ray.intersects_location(origins, directions, multiple_hits=False)
    return hits


@pytest.mark.slow
def test_the_lean_is_measured_on_the_surface_of_a_cloud_filled_under_it():
    """The hand choice plans again with the volume the view hides under the cloud added
    (:func:`hidden_below`); under a wall leaning 40 deg that volume reaches out to the
    rim at every depth, and the lean measured with it is under the pads' limit. The seen surface
    (:func:`seen_surface`) drops the added points, and the lean measured on it is the
    cone's."""
    seen = _rendered_cone(0.075, 0.04, 40.0)
    filled = np.concatenate([seen, hidden_below(seen, VIEWPOINT, 0.004)])
    surface = seen_surface(filled, VIEWPOINT)
    for cloud, lean_deg in ((seen, 40.0), (surface, 40.0)):
        sites = rim_sites(find_rim(cloud), 12, VIEWPOINT)
        assert sites
        for site in sites:
            assert math.degrees(site.lean_rad(cloud, 0.04)) == pytest.approx(lean_deg, abs=4.0)
    sites = rim_sites(find_rim(filled), 12, VIEWPOINT)
    assert np.median([math.degrees(site.lean_rad(filled, 0.04)) for site in sites]) < 24.0


def test_the_steepest_wall_a_pad_meets_with_three_rows():
    """Three rows' centres span 2 x 3.4 mm = 6.8 mm in height; a wall receding the touch
    tolerance, 3 mm, over them leans atan(3 / 6.8) = 23.8 deg; with no tolerance only a
    vertical wall."""
    assert math.degrees(lean_limit_rad(0.0034, 0.003)) == pytest.approx(23.81, abs=0.01)
    assert lean_limit_rad(0.0034, 0.0) == 0.0


def test_a_refusal_names_the_walls_lean_where_it_ruled_the_pinch_out():
    """The pinches' reason leads a refused plan's (with their count), though the
    enveloping grasps' reason is the more common; a plan that is not refused, or one
    without such pinches, is left as it is."""
    leaning = "the wall under the rim leans 52 deg from vertical (more than 24): edge"
    reasons = ["f1 meets no surface"] * 5 + [leaning.replace("52", "58"), leaning]
    candidates = [Candidate.rejected(0.0, 0.1, 0.0, reason) for reason in reasons]
    refused = plan_from_candidates("sdh", candidates, 0.1, 0.2)
    named = lean_named(refused, candidates)
    assert named.reason.startswith(WALL_LEANS + " 52-58 deg from vertical")
    assert "(2 pinches at the rim); none of 7 grasps is feasible (5 of them" in named.reason
    assert lean_named(refused, candidates[:5]) is refused
    ok = replace(refused, status="ok")
    assert lean_named(ok, candidates) is ok


def test_pads_on_a_leaning_walls_top_are_ruled_out_and_lower_down_kept():
    """A rim 100 mm in radius at z = 0.05, its wall leaning 40 deg: a pad touching it
    within 15 mm of the top from outside (at the rim) or inside (where the wall has come
    in 8 x tan 40 = 6.7 mm) is ruled out; one 20 mm down, or one touching the floor
    inside, is kept; at a lean within the limit nothing changes."""
    rim = Rim(np.zeros((0, 3)), np.array([0.0, 0.0, 0.05]), 0.1)

    def feasible(*contacts):
        rejected = Candidate.rejected(0.3, 0.04, 0.0, "")
        summary = replace(rejected.summary, feasible=True, score=0.1)
        return replace(rejected, summary=summary, predicted_contacts=np.array(contacts))

    outside = feasible([0.101, 0.0, 0.048], [0.1, 0.0, 0.045])
    inside = feasible([0.0, -0.088, 0.042])
    lower = feasible([0.08, 0.0, 0.03])
    floor = feasible([0.03, 0.0, 0.038])
    lean, limit = math.radians(40.0), math.radians(24.0)
    kept = off_leaning_wall([outside, inside, lower, floor], rim, lean, limit)
    assert [c.summary.feasible for c in kept] == [False, False, True, True]
    assert kept[0].summary.reason.startswith(WALL_LEANS + " 40 deg from vertical (more than 24)")
    assert kept[0].summary.closing_angle_deg == pytest.approx(math.degrees(0.3))
    assert kept[2] is lower
    steep = off_leaning_wall([outside, inside], rim, math.radians(20.0), limit)
    assert all(c.summary.feasible for c in steep)


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
