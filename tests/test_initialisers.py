"""Symmetry initialisers: VC against a brute-force reference and known scenes, PS from
synthetic contacts, and the simple ones."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.params import build
from pipeline.perception.visibility import visibility_violations
from pipeline.sim.hand_models import GRIPPERS
from pipeline.synthetic import (
    SyntheticObject,
    box_object,
    cylinder_object,
    synthetic_observation,
)
from pipeline.synthetic.tabletop import Box
from pipeline.types import (
    Contacts,
    PointCloud,
    SymmetryPlane,
)
from plugins.initialisers.given import GivenPlane
from plugins.initialisers.pca import PcaInitialiser
from plugins.initialisers.ps import PsInitialiser
from plugins.initialisers.vc import VcInitialiser
from plugins.planners.top_parallel import TopParallel
from plugins.segmenters.table_cluster import TableCluster

PG70 = GRIPPERS["pg70"]


def _violations_by_loop(points, planes, observation, tolerance_m):
    """Reference: mirror, project and compare one point at a time."""
    K = observation.intrinsics.matrix
    T_camera_robot = np.linalg.inv(observation.T_robot_camera)
    counts = []
    for plane in planes:
        count = 0
        for p in plane.mirror(points):
            q = T_camera_robot[:3, :3] @ p + T_camera_robot[:3, 3]
            if q[2] <= 0:
                continue
            u, v, _ = K @ (q / q[2])
            col, row = int(np.floor(u + 0.5)), int(np.floor(v + 0.5))
            if not (
                0 <= row < observation.depth_m.shape[0] and 0 <= col < observation.depth_m.shape[1]
            ):
                continue
            measured = observation.depth_m[row, col]
            if np.isfinite(measured) and q[2] < measured - tolerance_m:
                count += 1
        counts.append(count)
    return np.array(counts)


def _true_plane_error(plane, yaw, centre_xy, candidates):
    """Smallest (angle deg, offset mm) error against the true planes (object normals)."""
    best = (np.inf, np.inf)
    for nx, ny in candidates:
        normal = np.array(
            [np.cos(yaw) * nx - np.sin(yaw) * ny, np.sin(yaw) * nx + np.cos(yaw) * ny]
        )
        angle = np.degrees(np.arccos(min(1.0, abs(normal @ plane.normal[:2]))))
        offset = abs(plane.normal[:2] @ centre_xy - plane.offset_m)
        best = min(best, (angle, offset * 1000))
    return best


@pytest.fixture(scope="module")
def box_view():
    yaw = 0.35
    observation = synthetic_observation(
        box_object(0.042, 0.15, 0.12), (0.6, 0.0, yaw), rng=np.random.default_rng(2)
    )
    return yaw, observation, TableCluster().segment(observation)


def test_vectorised_score_equals_the_per_point_loop(box_view):
    _, observation, cloud = box_view
    points = cloud.points[::25]
    rng = np.random.default_rng(0)
    theta = rng.uniform(-np.pi, np.pi, 12)
    offset = np.array([np.cos(t) * 0.6 for t in theta]) + rng.uniform(-0.05, 0.05, 12)
    fast, _ = visibility_violations(
        points,
        theta,
        offset,
        observation.depth_m,
        observation.intrinsics,
        observation.T_robot_camera,
        tolerance_m=0.005,
    )
    planes = [SymmetryPlane(t, o) for t, o in zip(theta, offset, strict=True)]
    slow = _violations_by_loop(points, planes, observation, 0.005)
    assert slow.max() > 0 and slow.min() < len(points)  # the case discriminates
    np.testing.assert_array_equal(fast, slow)


def test_vc_finds_the_true_plane_of_a_symmetric_box(box_view):
    yaw, observation, cloud = box_view
    init = VcInitialiser().propose(cloud, observation)
    assert init.status == "ok"
    angle, offset = _true_plane_error(init.plane, yaw, np.array([0.6, 0.0]), [(1.0, 0.0)])
    assert angle < 5.0 and offset < 5.0
    scores = [h.score for h in init.hypotheses]
    assert scores == sorted(scores) and len(scores) == 19 * 25


def test_vc_scores_a_clearly_wrong_plane_badly(box_view):
    yaw, observation, cloud = box_view
    normal = np.array([np.cos(yaw), np.sin(yaw)])
    # Camera looks along +x: a plane 30 mm nearer the camera than the truth mirrors the
    # top face in front of the visible front face.
    true_offset = normal @ [0.6, 0.0]
    theta = np.array([yaw, yaw])
    offsets = np.array([true_offset, true_offset - 0.03])
    counts, _ = visibility_violations(
        cloud.points,
        theta,
        offsets,
        observation.depth_m,
        observation.intrinsics,
        observation.T_robot_camera,
    )
    fraction = counts / len(cloud)
    assert fraction[0] < 0.05 and fraction[1] > 0.3


def test_vc_rejects_when_every_hypothesis_is_hopeless(box_view):
    _, observation, cloud = box_view
    # A cloud floating 5 cm in front of what the camera saw: every mirror image of it lies
    # in free space.
    toward_camera = observation.T_robot_camera[:3, 2]
    floating = PointCloud(cloud.points - 0.05 * toward_camera)
    init = VcInitialiser().propose(floating, observation)
    assert init.status == "rejected"
    assert "free space" in init.reason and init.hypotheses[0].score > 0.2


def test_vc_on_a_cylinder_puts_the_plane_through_the_axis():
    observation = synthetic_observation(
        cylinder_object(0.0265, 0.12), (0.6, 0.05, 0.0), rng=np.random.default_rng(4)
    )
    cloud = TableCluster().segment(observation)
    init = VcInitialiser().propose(cloud, observation)
    assert abs(init.plane.normal[:2] @ [0.6, 0.05] - init.plane.offset_m) < 0.006


def test_vc_searches_every_orientation_on_a_round_footprint(box_view):
    # A cylinder's PCA axes are arbitrary: +-90 deg at the same 5 deg step (37 angles);
    # a box keeps +-45 deg around its seed.
    vc = VcInitialiser(VcInitialiser.Params(round_axis_ratio=1.5))
    observation = synthetic_observation(
        cylinder_object(0.04, 0.12), (0.6, 0.0, 0.0), rng=np.random.default_rng(4)
    )
    cylinder = vc.propose(TableCluster().segment(observation), observation)
    _, box_observation, box_cloud = box_view
    box = vc.propose(box_cloud, box_observation)
    for init, count, span_deg in ((cylinder, 37, 180.0), (box, 19, 90.0)):
        theta = np.unique(np.round([h.plane.theta_rad for h in init.hypotheses], 9))
        assert len(theta) == count
        assert np.degrees(theta.max() - theta.min()) == pytest.approx(span_deg)


def test_vc_searches_every_orientation_before_it_rejects():
    # A C-shaped footprint (a spine along y, arms toward -x at both ends) is mirror-symmetric
    # only about y = 0, across its major axis: no plane within 45 deg of containing that
    # axis is supported, so VC widens to +-90 deg (37 angles) and finds it.
    height = 0.04
    c_shape = SyntheticObject(
        "c-shape",
        (
            Box((0.03, 0.0, height / 2), (0.01, 0.08, height / 2)),
            Box((0.0, 0.07, height / 2), (0.03, 0.01, height / 2)),
            Box((0.0, -0.07, height / 2), (0.03, 0.01, height / 2)),
        ),
        ((0.0, 1.0),),
    )
    yaw = 0.35
    observation = synthetic_observation(c_shape, (0.6, 0.0, yaw), rng=np.random.default_rng(2))
    cloud = TableCluster().segment(observation)
    near_seed = VcInitialiser(VcInitialiser.Params(max_violation_fraction=1.0))
    assert near_seed.propose(cloud, observation).hypotheses[0].score > 0.2
    init = VcInitialiser().propose(cloud, observation)
    assert init.status == "ok" and len(init.hypotheses) == 37 * 25
    angle, offset = _true_plane_error(init.plane, yaw, np.array([0.6, 0.0]), [(0.0, 1.0)])
    assert angle < 5.0 and offset < 5.0


def test_pca_and_given():
    points = np.random.default_rng(0).uniform([0.0, -0.01, 0.0], [0.2, 0.01, 0.1], (5000, 3))
    init = PcaInitialiser().propose(PointCloud(points), None)
    assert abs(init.plane.normal[1]) == pytest.approx(1.0, abs=1e-3)
    assert init.plane.offset_m == pytest.approx(init.plane.normal @ points.mean(axis=0))
    params = build(GivenPlane.Params, {"normal_xy": [0.0, 2.0], "offset_m": 0.4}, "x")
    plane = GivenPlane(params).propose(PointCloud(points), None).plane
    assert plane.theta_rad == pytest.approx(np.pi / 2) and plane.offset_m == pytest.approx(0.2)
    with pytest.raises(ConfigError, match="normal_xy"):
        build(GivenPlane.Params, {"normal_xy": [0.0, 0.0]}, "initialiser.given")
    with pytest.raises(ConfigError, match="normal_xy"):
        build(GivenPlane.Params, {"normal_xy": [1.0]}, "initialiser.given")


def _pad_contacts(pad, face_x, normal_x, y_range, z_range):
    """A 6 x 14 grid of touching taxels on the plane x = face_x."""
    ys = np.linspace(*y_range, 6)
    zs = np.linspace(*z_range, 14)
    yy, zz = np.meshgrid(ys, zs)
    positions = np.column_stack([np.full(yy.size, face_x), yy.ravel(), zz.ravel()])
    normals = np.tile([normal_x, 0.0, 0.0], (len(positions), 1))
    return positions, normals, [pad] * len(positions)


def test_ps_refine_recovers_offset_and_bias_from_contacts():
    # Box 42 mm thick along x centred at x = 0.6, seen from -x; during the grasp it moves by
    # (+4, +2) mm. The pads touch the moved faces.
    observation = synthetic_observation(
        box_object(0.042, 0.15, 0.12), (0.6, 0.0, 0.0), rng=np.random.default_rng(6)
    )
    cloud = TableCluster().segment(observation)
    initialiser = PsInitialiser()
    proposal = initialiser.propose(cloud, observation)
    plan = TopParallel().plan(cloud, proposal, PG70)
    assert plan.status == "ok"
    motion = np.array([0.004, 0.002, 0.0])
    left = _pad_contacts("left", 0.579 + motion[0], 1.0, (-0.01, 0.01), (0.075, 0.11))
    right = _pad_contacts("right", 0.621 + motion[0], -1.0, (-0.01, 0.01), (0.075, 0.11))
    contacts = Contacts(
        positions=np.concatenate([left[0], right[0]]),
        normals=np.concatenate([left[1], right[1]]),
        pads=left[2] + right[2],
        taxel_indices=np.arange(168),
    )
    init = initialiser.refine(proposal, cloud, plan, contacts)
    normal = init.plane.normal
    assert abs(abs(normal[0]) - 1.0) < np.sin(np.deg2rad(3.0))
    # Plane through the true (unmoved) centre; bias = the motion along the pad normal.
    assert init.plane.offset_m == pytest.approx(normal[:2] @ [0.6, 0.0], abs=0.0015)
    np.testing.assert_allclose(init.bias.translation_m, [0.004, 0.0, 0.0], atol=0.0015)
    no_plan = initialiser.refine(proposal, cloud, None, contacts)
    assert no_plan.bias.translation_m @ no_plan.bias.translation_m == 0.0
    assert no_plan.plane.offset_m == pytest.approx(normal[:2] @ [0.604, 0.0], abs=0.0015)


def test_ties_between_hypotheses_go_to_the_most_compact_completion():
    from plugins.initialisers.vc import tie_spread

    # Two seen points at x = 0 and x = 0.02 m; planes x = 0.03 and x = 0.05 both without
    # violations (tied), a third at x = 0.01 with three.
    points = np.array([[0.0, 0.0, 0.1], [0.02, 0.01, 0.1]])
    theta = np.zeros(3)
    offset = np.array([0.05, 0.01, 0.03])
    violations = np.array([0, 3, 0])
    spread = tie_spread(points, theta, offset, violations, np.zeros(3))
    # mean |x - offset| by hand: (0.05 + 0.03) / 2 and (0.03 + 0.01) / 2; untied: 0
    assert spread == pytest.approx([0.04, 0.0, 0.02])
    assert np.lexsort((spread, np.zeros(3), violations))[0] == 2
    # A summed violation depth already separates hypotheses: no tie, no spread.
    depth = np.array([0.0, 0.0, 0.001])
    assert tie_spread(points, theta, offset, violations, depth) == pytest.approx(np.zeros(3))
