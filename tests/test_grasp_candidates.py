"""Grasp candidates: SDH-2 pre-shape geometry against the URDF's forward kinematics, pad
coverage against hand-computed cases, and the ranked planners on synthetic views."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yourdfpy
from test_planners import PG70, _true_plane, _view

from pipeline.planning import sdh_candidates, sdh_geometry
from pipeline.planning.candidate import (
    BEYOND_CENTRE,
    BLIND_PAD_FACTOR,
    CandidateCloud,
    CandidateSettings,
    height_grid,
)
from pipeline.planning.grasp_candidates import common_reason
from pipeline.planning.grasp_geometry import front_to_back, rotate_z
from pipeline.planning.pad_contact import (
    flat_pad_taxels,
    pad_coverage,
    pad_coverages,
    sdh_distal_taxels,
)
from pipeline.planning.parallel_candidates import ParallelHand, front_jaw_gap, parallel_candidate
from pipeline.synthetic import box_object, cylinder_object
from pipeline.types import Bias, PadLayout, PointCloud, SymmetryInit, SymmetryPlane
from plugins.planners.top_parallel import TopParallel
from plugins.planners.top_three_finger import TopThreeFinger
from robots import ROOT

PAD = PadLayout("left", "left_pad", 14, 6, 0.0034)
DISTAL = PadLayout("thumb_distal", "thumb_distal_pad", 13, 6, 0.0034)

SDH = sdh_geometry.shipped()  # the SDH-2's kinematics, read from its URDF


@pytest.fixture(scope="module")
def sdh2() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(ROOT / "sdh2.urdf"))


def _configure(robot: yourdfpy.URDF, spread: float, alpha: float) -> None:
    joints = {"f1_base": spread, "f2_base": spread}
    for finger in SDH.fingers:
        joints[f"{finger}_proximal"] = alpha
        joints[f"{finger}_distal"] = -alpha
    robot.update_cfg(np.array([joints[name] for name in robot.actuated_joint_names]))


@pytest.mark.parametrize("spread_deg", [0.0, 30.0, 60.0, 90.0])
@pytest.mark.parametrize("alpha_deg", [-80.0, -25.0, 0.0, 20.0])
def test_distal_pad_reach_depth_and_facing_match_the_urdf(sdh2, spread_deg, alpha_deg):
    spread, alpha = math.radians(spread_deg), math.radians(alpha_deg)
    _configure(sdh2, spread, alpha)
    facings = SDH.finger_facings(spread)
    for i, finger in enumerate(SDH.fingers):
        pad = sdh2.get_transform(f"{finger}_distal_pad", "palm")
        base = sdh2.get_transform(f"{finger}_knuckle", "palm")
        # The pad frame sits on the pad's flat surface, its normal along the facing.
        np.testing.assert_allclose(pad[:2, 2], facings[i], atol=1e-6)
        assert pad[2, 2] == pytest.approx(0.0, abs=1e-6)
        np.testing.assert_allclose(base[:2, 3], SDH.bases_m[i], atol=1e-5)
        along = (pad[:2, 3] - base[:2, 3]) @ facings[i]
        assert along == pytest.approx(SDH.reach_m(alpha), abs=1e-6)
        assert pad[2, 3] == pytest.approx(SDH.distal_pad_depth_m(alpha), abs=1e-6)
        # The fingertip: the distal link's end, the profile's deepest point.
        tip = sdh2.get_transform(f"{finger}_distal", "palm") @ [0.0, 0.0, SDH.distal_length_m, 1]
        _, depth = SDH.finger_profile(alpha)
        assert depth.max() == pytest.approx(tip[2], abs=1e-6)
    assert SDH.alpha_for_reach(SDH.reach_m(alpha)) == pytest.approx(alpha)
    assert SDH.alpha_for_opening(SDH.opening_for_alpha(alpha)) == pytest.approx(alpha)


def test_finger_profile_covers_the_finger_and_is_exact_behind_the_pad(sdh2):
    """Dense oracle: sample the finger's collision boxes (links and pads) from the URDF and
    take the deepest sample per millimetre along the facing. The profile never misses
    finger material; it is exact except in front of the distal link's body, where it takes
    the tip's depth for the pad that curves up and away from it."""
    alpha = math.radians(-30.0)
    _configure(sdh2, math.radians(60.0), alpha)
    grid, depth = SDH.finger_profile(alpha)
    base = sdh2.get_transform("thumb_knuckle", "palm")
    samples = []
    for link in ("thumb_proximal", "thumb_distal", "thumb_proximal_pad", "thumb_distal_pad"):
        T_link = sdh2.get_transform(link, "palm")
        for collision in sdh2.link_map[link].collisions:
            size = np.asarray(collision.geometry.box.size)
            axes = [np.linspace(-s / 2, s / 2, 15) for s in size]
            local = np.stack(np.meshgrid(*axes), axis=-1).reshape(-1, 3)
            T = T_link @ collision.origin
            samples.append(local @ T[:3, :3].T + T[:3, 3])
    points = np.concatenate(samples)
    t = points[:, 0] - base[0, 3]  # the thumb faces +x
    distal_front = SDH.reach_m(alpha) - SDH.distal_pad_offset_m + 0.005
    for value in np.linspace(t.min() + 0.003, t.max() - 0.003, 40):
        deepest = points[np.abs(t - value) < 0.0015, 2].max()
        profile = depth[int(np.argmin(np.abs(grid - value)))]
        assert profile >= deepest - 0.0025
        if value < distal_front:
            assert profile == pytest.approx(deepest, abs=0.0025)


def test_pad_coverage_on_a_flat_face_and_on_a_cylinder():
    rng = np.random.default_rng(0)
    # A flat face 30 mm ahead, facing the pad: every taxel touches.
    face = np.column_stack(
        [np.full(4000, 0.03), rng.uniform(-0.03, 0.03, 4000), rng.uniform(0.0, 0.1, 4000)]
    )
    taxels = flat_pad_taxels(PAD, 0.05)
    contact = pad_coverage(face, np.zeros(3), np.array([1.0, 0, 0]), taxels, 0.003)
    assert contact.touch_m == pytest.approx(0.03)
    assert contact.coverage == 1.0
    # A vertical cylinder of radius r: a column at lateral u is touched when the surface
    # there lies within the tolerance, r - sqrt(r^2 - u^2) <= tol.
    radius, tol = 0.02, 0.003
    angle = rng.uniform(-np.pi / 2, np.pi / 2, 40000)
    cylinder = np.column_stack(
        [0.05 - radius * np.cos(angle), radius * np.sin(angle), rng.uniform(0.0, 0.1, 40000)]
    )
    contact = pad_coverage(cylinder, np.zeros(3), np.array([1.0, 0, 0]), taxels, tol)
    assert contact.touch_m == pytest.approx(0.05 - radius, abs=2e-4)
    u = (np.arange(6) - 2.5) * 0.0034
    expected = np.sum(radius - np.sqrt(radius**2 - u**2) <= tol) / 6
    assert contact.coverage == pytest.approx(expected)
    # Nothing in front of the pad.
    assert pad_coverage(face, np.zeros(3), np.array([0, 1.0, 0]), taxels, tol) is None


def test_pad_coverage_meets_the_near_side_of_a_cloud_with_two_sides():
    # A completed box, front face 30 mm ahead and its mirrored back 70 mm ahead, as many
    # points on each: the pad meets the front, and only its points are in the contact.
    y, z = np.meshgrid(np.arange(-0.03, 0.03, 0.001), np.arange(0.0, 0.1, 0.001))
    face = np.column_stack([np.full(y.size, 0.03), y.ravel(), z.ravel()])
    both = np.vstack([face, face + np.array([0.04, 0.0, 0.0])])
    taxels = flat_pad_taxels(PAD, 0.05)
    contact = pad_coverage(both, np.zeros(3), np.array([1.0, 0, 0]), taxels, 0.003)
    assert contact.touch_m == pytest.approx(0.03)
    assert contact.coverage == 1.0
    assert np.all(contact.points[:, 0] == 0.03)


def test_pads_found_together_meet_what_each_meets_alone():
    # A box 40 x 60 mm around the origin, 0-100 mm high, seen by three pads closing on it
    # from three sides at 50 mm, and a fourth pad beside it that meets nothing. Found in
    # one pass, each pad's contact is the one it finds alone, on the whole cloud.
    rng = np.random.default_rng(2)
    u, z = rng.uniform(-1.0, 1.0, 3000), rng.uniform(0.0, 0.1, 3000)
    box = np.vstack(
        [
            np.column_stack([np.full(3000, -0.02), 0.03 * u, z]),
            np.column_stack([np.full(3000, 0.02), 0.03 * u, z]),
            np.column_stack([0.02 * u, np.full(3000, 0.03), z]),
        ]
    )
    origins = np.array([[-0.1, 0.0, 0.0], [0.1, 0.005, 0.0], [0.0, 0.1, 0.0], [0.2, 0.2, 0.0]])
    directions = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, -1.0, 0], [1.0, 0, 0]])
    taxels = sdh_distal_taxels(DISTAL, 0.05)
    # A flat face touches the 4 flat rows and the curved ones recessed within 3 mm.
    s = (np.arange(1, 10) - 0.5) * 0.0034
    rows = 4 + np.sum(0.059 * (1 - np.cos(s / 0.059)) <= 0.003)
    together = pad_coverages(box[::-1], origins, directions, taxels, 0.003)
    assert together[3] is None
    for contact, origin, direction in zip(together[:3], origins[:3], directions[:3], strict=True):
        alone = pad_coverage(box[::-1], origin, direction, taxels, 0.003)
        assert contact.touch_m == alone.touch_m
        assert contact.coverage == alone.coverage == pytest.approx(rows / 13)
        np.testing.assert_array_equal(contact.points, alone.points)
        assert contact.inclination_rad == alone.inclination_rad
    # Each touch is the face's position along the pad's motion: 20, 20 and 30 mm from the
    # box's centre, before it.
    touches = [c.touch_m for c in together[:3]]
    np.testing.assert_allclose(touches, [-0.02, -0.02, -0.03], atol=1e-9)


def test_the_distal_pad_tip_curves_away_from_a_flat_face():
    """The 9 tip rows lie on a 59 mm cylinder: a row s along the curve is recessed
    r (1 - cos(s / r)); only rows within the tolerance touch a flat face."""
    taxels = sdh_distal_taxels(DISTAL, 0.05)
    s = (np.arange(1, 10) - 0.5) * 0.0034
    np.testing.assert_allclose(taxels.row_recess[4:], 0.059 * (1 - np.cos(s / 0.059)), atol=1e-9)
    rng = np.random.default_rng(1)
    face = np.column_stack(
        [np.full(6000, 0.03), rng.uniform(-0.03, 0.03, 6000), rng.uniform(0.0, 0.1, 6000)]
    )
    contact = pad_coverage(face, np.zeros(3), np.array([1.0, 0, 0]), taxels, 0.002)
    rows = 4 + np.sum(0.059 * (1 - np.cos(s / 0.059)) <= 0.002)
    assert contact.coverage == pytest.approx(rows / 13)


def test_height_grid_runs_from_the_top_down_and_ends_at_the_bottom():
    np.testing.assert_allclose(height_grid(0.05, 0.08, 0.01), [0.08, 0.07, 0.06, 0.05])
    np.testing.assert_allclose(height_grid(0.05, 0.085, 0.01), [0.085, 0.075, 0.065, 0.055, 0.05])
    np.testing.assert_allclose(height_grid(0.05, 0.04, 0.01), [0.05])


# ---------------------------------------------------------------- ranked planners


def test_sdh_pre_shape_puts_the_pads_on_a_narrow_cylinder_at_the_chosen_height():
    from pipeline.sim.hands import GRIPPERS

    cloud = _view(cylinder_object(radius_m=0.0225, height_m=0.12))
    plan = TopThreeFinger().plan(cloud, _true_plane(), GRIPPERS["sdh"])
    assert plan.status == "ok", plan.reason
    best = plan.candidates[0]
    assert best.feasible and min(best.contact_coverage) > 0.15
    # Pre-shaped around the object with the descent clearance, far from fully open.
    alpha_open = SDH.alpha_for_opening(plan.opening_m)
    assert 0.045 + 2 * 0.01 < plan.opening_m < 0.13
    # Every finger's contact angle is where its pad meets the 22.5 mm radius; at that
    # angle the distal pad centre is at the planned height.
    facings = SDH.finger_facings(plan.spread_rad)
    rotation = plan.T_robot_hand[:2, :2]
    centre = np.array([0.6, 0.0])
    for base, facing in zip(SDH.bases_m, facings, strict=True):
        base_robot = plan.T_robot_hand[:2, 3] + rotation @ base
        facing_robot = rotation @ facing
        # distance along the facing to the cylinder's near surface
        offset = centre - base_robot
        along = offset @ facing_robot
        across = offset @ np.array([-facing_robot[1], facing_robot[0]])
        surface = along - math.sqrt(0.0225**2 - min(across**2, 0.0225**2))
        alpha = SDH.alpha_for_reach(surface)
        assert alpha > alpha_open
        depth = SDH.distal_pad_depth_m(alpha)
        assert plan.T_robot_hand[2, 3] - depth == pytest.approx(best.height_m, abs=0.004)


def test_parallel_candidates_close_across_the_thin_side_of_a_turned_box():
    from pipeline.sim.hands import GRIPPERS

    yaw = math.radians(50.0)
    cloud = _view(box_object(thickness_m=0.042, length_m=0.17, height_m=0.146), yaw)
    # The proposal is the box's other mirror plane, across its length: the paper's rule
    # would close along the 170 mm length; the candidates turn to the thin side.
    plane = _true_plane(yaw + math.radians(90.0))
    paper = TopParallel(TopParallel.Params(strategy="paper")).plan(cloud, plane, GRIPPERS["pg70"])
    assert paper.status == "refused"
    plan = TopParallel().plan(cloud, plane, GRIPPERS["pg70"])
    assert plan.status == "ok", plan.reason
    thin = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    assert abs(plan.closing_direction @ thin) > math.cos(math.radians(16.0))
    ranked = [c.score for c in plan.candidates]
    assert ranked == sorted(ranked, reverse=True)
    assert plan.score == ranked[0] > 0.0


def test_common_reason_counts_reasons_that_differ_only_in_their_numbers_together():
    reasons = [
        "no surface before the back pad",
        "82 mm wide between the jaws' paths, aperture 65 mm",
        "no surface before the back pad",
        "116 mm wide between the jaws' paths, aperture 65 mm",
        "59 mm wide between the jaws' paths, aperture 65 mm",
        "f1 meets no surface",
        "f2 meets no surface",
    ]
    assert common_reason(reasons) == (
        "59-116 mm wide between the jaws' paths, aperture 65 mm",
        3,
    )
    # A finger's name is not a number; on a tie the kind met first wins.
    assert common_reason(reasons[5:]) == ("f1 meets no surface", 1)
    assert common_reason(["pad 2.5 mm off", "pad 12.25 mm off"]) == ("pad 2.5-12.25 mm off", 2)


def test_a_box_wider_than_the_jaws_is_refused_with_its_widths():
    from pipeline.sim.hands import GRIPPERS

    cloud = _view(box_object(thickness_m=0.1, length_m=0.12, height_m=0.1), 0.0)
    plan = TopParallel().plan(cloud, _true_plane(0.0), GRIPPERS["pg70"])
    assert plan.status == "refused"
    too_wide = [c for c in plan.candidates if "wide between the jaws' paths" in c.reason]
    widths = [float(c.reason.split(" mm")[0]) for c in too_wide]
    assert len(set(widths)) > 1
    assert plan.reason == (
        f"none of {len(plan.candidates)} grasps is feasible ({len(too_wide)} of them: "
        f"{min(widths):.0f}-{max(widths):.0f} mm wide between the jaws' paths, aperture 65 mm)"
    )


@pytest.mark.parametrize(
    ("width_mm", "front_mm"),
    [
        (40.0, 7.5),  # room 25, less the 10 mm back margin: half of 15 each side
        (30.0, 10.0),  # room enough: the jaw clearance
        (51.0, 7.0),  # no room for the margin: the 14 mm split evenly
        (6.0, 30.5),  # back jaw reaches at most 32.5 - 4 mm: the front stands back
    ],
)
def test_front_jaw_gap_by_hand(width_mm, front_mm):
    gap = front_jaw_gap(0.065, width_mm / 1e3, 0.004, 0.01, 0.01)
    assert gap == pytest.approx(front_mm / 1e3)
    back_mm = 65.0 - width_mm - front_mm
    assert min(14.0, (65.0 - width_mm) / 2) - 1e-9 <= back_mm <= 32.5 - 4.0 + 1e-9


def test_front_jaw_gap_refuses_an_object_that_leaves_no_clearance():
    assert front_jaw_gap(0.065, 0.058, 0.004, 0.01, 0.01) is None


def test_front_to_back_points_away_from_the_camera_at_a_wall_seen_level():
    # The near half of a 41 mm cup wall, every height seen alike: the lower quarter of the
    # cloud says nothing about which side is in front, the camera's position does.
    angles = np.radians(np.arange(95.0, 266.0, 5.0))
    heights = np.arange(0.02, 0.095, 0.005)
    a, z = np.meshgrid(angles, heights)
    wall = np.column_stack([0.041 * np.cos(a.ravel()), 0.041 * np.sin(a.ravel()), z.ravel()])
    camera = np.array([-0.7, -0.02, 0.1])
    for heading_deg in (0.0, 50.0, 130.0, 180.0, -100.0):
        d = np.array([math.cos(math.radians(heading_deg)), math.sin(math.radians(heading_deg)), 0])
        result = front_to_back(wall, d, camera)
        away = (wall.mean(axis=0) - camera) * [1.0, 1.0, 0.0]
        assert result @ away > 0.0
        assert abs(result @ d) == pytest.approx(1.0)


JAW_SETTINGS = CandidateSettings(
    table_height_m=0.0,
    table_clearance_m=0.005,
    descent_clearance_m=0.004,
    touch_tolerance_m=0.002,
    tipping_weight=0.5,
)


def _jaw_hand():
    from pipeline.sim.hands import GRIPPERS

    return ParallelHand.of(GRIPPERS["pg70"], "test")


def _jaws_closing_along_y(visible: np.ndarray, completed: np.ndarray):
    """The PG-70 candidate closing along +y through the origin, pads centred 60 mm up."""
    return parallel_candidate(
        CandidateCloud(visible, completed),
        np.zeros(3),
        np.array([0.0, 1.0, 0.0]),
        0.0,
        0.06,
        _jaw_hand(),
        JAW_SETTINGS,
        jaw_clearance_m=0.01,
        back_margin_m=0.01,
    )


def _wall(along_m: float, thickness_m: float = 0.006, half_width_m: float = 0.02) -> np.ndarray:
    """A vertical wall across +y, ``half_width_m`` either side of x = 0, from ``along_m`` to
    ``along_m + thickness_m`` along y, 20-90 mm high."""
    x, y, z = np.meshgrid(
        np.arange(-half_width_m, half_width_m + 1e-9, 0.002),
        np.arange(along_m, along_m + thickness_m + 1e-9, 0.002),
        np.arange(0.02, 0.0901, 0.002),
    )
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()])


@pytest.mark.parametrize(
    ("visible_at", "hidden_at", "reason"),
    [
        # The column holds one wall beyond the centre: the jaws would pinch it.
        (0.035, None, "the jaws would close on one wall, not around the object"),
        # ... or one wall before it.
        (-0.04, None, "the jaws would close on one wall, not around the object"),
        # Two walls 30 mm apart around the centre: a grasp.
        (-0.021, 0.009, ""),
    ],
)
def test_parallel_candidate_closes_around_the_centre(visible_at, hidden_at, reason):
    visible = _wall(visible_at)
    completed = visible if hidden_at is None else np.vstack([visible, _wall(hidden_at)])
    candidate = _jaws_closing_along_y(visible, completed)
    assert candidate.summary.reason == reason
    assert candidate.summary.feasible == (reason == "")


def test_a_back_pad_that_would_meet_the_front_from_inside_counts_as_blind():
    # The completed back covers the jaw's path only beside the pad (x 12-20 mm; the pad's
    # columns span about +-10 mm): where the pad closes, the model has a hole, and the
    # nearest surface it would meet is the front wall's inner face, before the centre.
    front = _wall(-0.021)
    back = _wall(0.009)
    whole = _jaws_closing_along_y(front, np.vstack([front, back]))
    assert whole.summary.feasible and min(whole.summary.contact_coverage) > 0.5
    holed = _jaws_closing_along_y(front, np.vstack([front, back[back[:, 0] >= 0.012]]))
    # The jaws stand where they did (the column beside the pad still holds the back); the
    # back pad's contact is unknown, and the grasp keeps a tenth of the score its front pad
    # alone gives (here the same as both pads').
    assert holed.summary.feasible
    np.testing.assert_allclose(holed.T_robot_hand, whole.T_robot_hand)
    assert holed.summary.contact_coverage == (whole.summary.contact_coverage[0], 0.0)
    assert holed.summary.score == pytest.approx(BLIND_PAD_FACTOR * whole.summary.score)


def test_sdh_fingers_that_would_meet_the_front_from_inside_are_rejected():
    # Fingers 1 and 2 close 33 mm either side of the closing line, where this model has no
    # back (it covers only +-12 mm): they would pass the centre and meet the front wall's
    # inner face.
    front = _wall(-0.021, half_width_m=0.05)
    centre = np.array([0.0, 0.0, 0.045])
    for back, feasible in (
        (_wall(0.015, half_width_m=0.05), True),
        (_wall(0.015, half_width_m=0.012), False),
    ):
        candidate = sdh_candidates.sdh_candidate(
            CandidateCloud(front, np.vstack([front, back])),
            centre,
            np.array([0.0, 1.0, 0.0]),
            0.0,
            0.06,
            0.0,
            sdh_candidates.SdhHand(SDH, DISTAL, 0.3),
            JAW_SETTINGS,
        )
        assert candidate.summary.feasible == feasible
        assert candidate.summary.reason == ("" if feasible else BEYOND_CENTRE)


@pytest.mark.parametrize(
    ("top_m", "edge"),
    [
        (0.080, True),  # between the pad's top row (72 mm) and the distal joint (92 mm)
        (0.120, False),  # the side goes on above the joint: the link runs along it
        (0.066, False),  # the side ends below the pad's top row: the pad reaches over it
    ],
)
def test_a_top_edge_behind_the_distal_link_is_found(top_m, edge):
    y, z = np.meshgrid(np.arange(-0.02, 0.0201, 0.002), np.arange(0.0, top_m + 1e-9, 0.002))
    wall = np.column_stack([np.full(y.size, 0.05), y.ravel(), z.ravel()])
    taxels = sdh_distal_taxels(DISTAL, 0.05)
    direction = np.array([1.0, 0.0, 0.0])
    contact = pad_coverage(wall, np.zeros(3), direction, taxels, 0.003)
    assert contact.touch_m == pytest.approx(0.05)
    pad_top, joint = sdh_candidates._pad_top_and_joint(SDH, taxels)
    found = sdh_candidates._top_edge_above_pad(
        SDH, wall, np.zeros(3), direction, pad_top, joint, contact
    )
    assert found is edge


def test_a_jaw_finger_that_meets_a_shoulder_below_its_pad_is_rejected():
    # Two walls around the centre, pads centred 60 mm up (rows 36-84 mm, fingertip 31 mm).
    # Below the front pad a shoulder stands 10 mm proud of the wall: the finger, 3 mm
    # behind the pad's surface, meets it first.
    front, back = _wall(-0.021), _wall(0.009)
    shoulder = _wall(-0.031)
    shoulder = shoulder[shoulder[:, 2] < 0.035]
    for visible, reason in (
        (front, ""),
        (np.vstack([front, shoulder]), "the front finger meets the object before its pad"),
    ):
        candidate = _jaws_closing_along_y(visible, np.vstack([visible, back]))
        assert candidate.summary.reason == reason


def test_the_lowest_pad_height_is_not_below_the_clearance_it_is_computed_from():
    # The lowest height a planner tries puts the fingertips exactly at the clearance: table
    # + clearance + pad-to-fingertip, less pad-to-fingertip, is that bound only up to float
    # rounding, which put it a fraction of a nanometre below in about one case in five.
    rng = np.random.default_rng(3)
    for table in rng.uniform(-0.05, 0.05, 200):
        settings = CandidateSettings(
            table_height_m=float(table),
            table_clearance_m=0.01,
            descent_clearance_m=0.004,
            touch_tolerance_m=0.002,
            tipping_weight=0.5,
        )
        lowest = float(table) + 0.01 + 0.029
        assert not settings.below_clearance(lowest - 0.029)
        assert settings.below_clearance(lowest - 0.029 - 1e-6)


@pytest.mark.parametrize(("proud_m", "feasible"), [(0.001, True), (0.004, False)])
def test_a_step_below_the_jaw_s_taxels_stops_it_on_the_pad_s_bare_edge(proud_m, feasible):
    # Pads centred 60 mm up: taxel rows from 37.9 mm, the pad's bare lower edge 35-36.2 mm
    # flush with its surface, the finger 3 mm behind it below. The front's lower part, up
    # to 36 mm, stands proud of the part the taxels face: 1 mm is within the tolerance
    # (the taxels press too), 4 mm is not (the pad's edge stops the jaw with every taxel
    # short of the surface, as a stepped brick's body below its studs did).
    # One layer each, so that each taxel's surface is the wall's face.
    front, back = _wall(-0.021, 0.0), _wall(0.009, 0.0)
    step = _wall(-0.021 - proud_m, 0.0)
    visible = np.vstack([front[front[:, 2] > 0.0365], step[step[:, 2] <= 0.036]])
    candidate = _jaws_closing_along_y(visible, np.vstack([visible, back]))
    assert candidate.summary.feasible is feasible
    if not feasible:
        assert candidate.summary.reason == "the front finger meets the object before its pad"


def _reach_to_lying_cylinder(start, closing, lateral, across, up, radius_m, axis):
    """How far each point of a vertical jaw face - ``across`` along ``lateral`` and ``up``
    in height from ``start`` - travels along ``closing`` to a cylinder of ``radius_m``
    lying on the table z = 0 with its axis along ``axis`` through (0, 0, radius_m) (inf
    where it misses): the closed form of each ray's first intersection."""
    rays = start + np.outer(across, lateral) + np.outer(up, [0.0, 0.0, 1.0])
    w = rays - np.array([0.0, 0.0, radius_m])
    w_perp = w - np.outer(w @ axis, axis)
    d_perp = closing - (closing @ axis) * axis
    a, b = d_perp @ d_perp, 2.0 * w_perp @ d_perp
    c = np.einsum("ij,ij->i", w_perp, w_perp) - radius_m**2
    disc = b * b - 4.0 * a * c
    return np.where(disc >= 0.0, (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a), np.inf)


def test_a_lying_cylinder_is_pressed_by_the_jaws_taxels():
    # A cylinder 12-20 mm in radius lying on the table, seen from one side with 1 mm of
    # depth noise; the planner's PG-70 grasp, checked against the true cylinder: where each
    # jaw's face (its pad flush, the finger 3 mm behind it beside and below) first meets
    # it, the nearest taxel must be within 1 mm (the simulated taxels' contact threshold),
    # not left short while the jaw's bare part presses the cylinder's widest line.
    hand = _jaw_hand()
    rng = np.random.default_rng(4)
    for radius in (0.012, 0.016, 0.02):
        yaw = rng.uniform(0.0, 2.0 * np.pi)
        axis = np.array([np.cos(yaw), np.sin(yaw), 0.0])
        side = np.array([-axis[1], axis[0], 0.0])
        # The camera 0.6 m up and 0.6 m out, up to 40 deg from square to the axis.
        camera = 0.6 * rotate_z(side, rng.uniform(-0.7, 0.7)) + [0.0, 0.0, 0.6]
        t, along = np.meshgrid(
            np.linspace(0, 2 * np.pi, 240, endpoint=False), np.arange(-0.06, 0.06, 0.0015)
        )
        normals = np.cos(t).reshape(-1, 1) * side + np.sin(t).reshape(-1, 1) * [0.0, 0.0, 1.0]
        points = along.reshape(-1, 1) * axis + radius * normals + [0.0, 0.0, radius]
        view = (camera - points) / np.linalg.norm(camera - points, axis=1)[:, None]
        seen = np.einsum("ij,ij->i", normals, view) > 0.05
        points = points[seen] - view[seen] * rng.normal(0.0, 0.001, (np.count_nonzero(seen), 1))
        plane = SymmetryInit(SymmetryPlane(math.atan2(side[1], side[0]), 0.0), Bias())
        plan = TopParallel(TopParallel.Params(cloud_base_above_table_m=0.0)).plan(
            PointCloud(points, "robot", viewpoint_m=camera), plane, PG70
        )
        assert plan.status == "ok", plan.reason
        direction = plan.closing_direction
        lateral = np.array([-direction[1], direction[0], 0.0])
        pad_z = plan.T_robot_hand[2, 3] - hand.palm_to_pad_centre_m
        u, z = np.meshgrid(
            np.arange(-hand.jaw_half_width_m, hand.jaw_half_width_m + 1e-9, 2e-4),
            np.arange(pad_z - hand.pad_centre_to_fingertip_m, pad_z + 0.0236, 2e-4),
        )
        on_pad = (np.abs(u) <= hand.pad_width_m / 2) & (z >= pad_z - hand.pad_length_m / 2)
        recess = np.where(on_pad, 0.0, hand.finger_recess_m).ravel()
        pitch = hand.pad.pitch_m
        taxel_u, taxel_z = np.meshgrid(
            (np.arange(hand.pad.cols) - (hand.pad.cols - 1) / 2) * pitch,
            pad_z + (np.arange(hand.pad.rows) - (hand.pad.rows - 1) / 2) * pitch,
        )
        for sign in (1.0, -1.0):
            closing = sign * direction
            start = plan.T_robot_hand[:3, 3] * [1.0, 1.0, 0.0] - 0.2 * closing
            jaw = (start, closing, lateral)
            stop = np.min(_reach_to_lying_cylinder(*jaw, u, z, radius, axis) + recess)
            nearest_taxel = np.min(_reach_to_lying_cylinder(*jaw, taxel_u, taxel_z, radius, axis))
            assert nearest_taxel - stop <= 0.001, (radius, sign)
