"""The rotation axis of any direction from one view: generated bodies of revolution whose
axis is known, seen from one side only."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.symmetry.axis_fit import fit_any_axis, tilt_deg
from pipeline.symmetry.kinds import complete, plane_through_axis
from pipeline.symmetry.search import half_sphere
from pipeline.types import Symmetry


def seen_body(axis_direction, axis_point, radius_of, length, view, rng, noise=0.0005, n=3000):
    """Points of the surface of revolution ``r(t) = radius_of(t)``, ``t`` in ``[0, length]``
    about the given axis, only where the surface faces ``view`` (a unit vector toward the
    camera) by more than 0.2, with Gaussian noise along the radius."""
    d = np.asarray(axis_direction, float) / np.linalg.norm(axis_direction)
    u, v = Symmetry("axis", d, np.zeros(3)).across_axes()
    t = rng.uniform(0.0, length, 4 * n)
    angle = rng.uniform(0.0, 2.0 * math.pi, 4 * n)
    outward = np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v
    # The surface's normal leans along the axis where the radius changes.
    slope = (radius_of(t + 1e-6) - radius_of(t - 1e-6)) / 2e-6
    normal = outward - slope[:, None] * d
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    seen = normal @ view > 0.2
    radius = radius_of(t) + noise * rng.standard_normal(len(t))
    points = axis_point + t[:, None] * d + radius[:, None] * outward
    return points[seen][:n]


def can(t):
    """A can's profile: 33 mm everywhere (m)."""
    return np.full_like(t, 0.033)


def cone(t):
    """A cone's profile: 40 mm tapering to 25 mm over 10 cm (m)."""
    return 0.04 - 0.15 * t


def axis_errors(fit, direction, point):
    """(angle deg, distance mm of ``point`` from the fitted axis)."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    angle = math.degrees(math.acos(min(1.0, abs(float(fit.axis.direction @ d)))))
    relative = np.asarray(point) - fit.axis.point_m
    along = relative @ fit.axis.direction
    return angle, 1e3 * float(np.linalg.norm(relative - along * fit.axis.direction))


@pytest.mark.parametrize("index", range(6))
def test_the_axis_of_a_seen_cylinder_or_cone_at_a_random_direction_is_recovered(index):
    rng = np.random.default_rng(100 + index)
    direction = half_sphere(50)[rng.integers(50)] * rng.choice([-1.0, 1.0])
    point = np.array([0.6, 0.0, 0.05]) + rng.uniform(-0.05, 0.05, 3)
    view = rng.standard_normal(3)
    view -= (view @ direction) * direction  # the camera sees the body from its side
    view = view / np.linalg.norm(view) + 0.3 * direction * rng.uniform(-1.0, 1.0)
    view /= np.linalg.norm(view)
    points = seen_body(direction, point, cone if index % 2 else can, 0.1, view, rng)
    fit = fit_any_axis(points)
    assert fit is not None
    angle, distance = axis_errors(fit, direction, point)
    # Half a millimetre of noise over the seen half of a 10 cm body.
    assert angle < 2.0
    assert distance < 2.0
    assert fit.profile_rms_m == pytest.approx(0.0005, rel=0.35)


def test_a_lying_can_seen_from_above_has_a_level_axis():
    rng = np.random.default_rng(7)
    direction = np.array([math.cos(0.4), math.sin(0.4), 0.0])
    point = np.array([0.6, 0.1, 0.033])  # resting on the table z = 0
    view = np.array([-0.7, 0.0, 0.7]) / math.sqrt(0.98)
    points = seen_body(direction, point, can, 0.12, view, rng)
    fit = fit_any_axis(points)
    angle, distance = axis_errors(fit, direction, point)
    assert angle < 1.5 and distance < 1.5
    assert tilt_deg(fit.axis) > 88.0
    # Its plane for the estimator is the vertical one through the axis.
    plane = plane_through_axis(fit.axis, np.array([-0.4, 0.1, 0.7]))
    assert abs(plane.normal @ direction) < math.sin(math.radians(1.5))
    assert abs(plane.normal[:2] @ point[:2] - plane.offset_m) < 0.0015
    # The sweep closes the can, clipped at the table.
    model = complete(points, fit.axis, table_z_m=0.0)
    assert model[:, 2].min() >= 0.0
    assert len(model) < 12 * len(points)


def test_a_box_fits_no_axis_of_any_direction():
    rng = np.random.default_rng(3)
    # Three faces of a 60 x 100 x 80 mm box seen from a corner.
    a, b = rng.uniform(0.0, 1.0, (2, 1500))
    faces = [
        np.column_stack([np.zeros_like(a), 0.1 * a, 0.08 * b]),
        np.column_stack([0.06 * a, np.zeros_like(a), 0.08 * b]),
        np.column_stack([0.06 * a, 0.1 * b, np.full_like(a, 0.08)]),
    ]
    points = np.vstack(faces) + 0.0005 * rng.standard_normal((4500, 3))
    fit = fit_any_axis(points)
    assert fit is None or fit.profile_rms_m > 0.003


@pytest.mark.slow
def test_the_camera_settles_an_axis_the_profile_leaves_tilted():
    from pipeline.symmetry.axis_fit import AxisFit, fit_axis
    from pipeline.symmetry.kinds import settled_axis
    from pipeline.synthetic import cylinder_object, synthetic_observation
    from plugins.segmenters.table_cluster import TableCluster

    observation = synthetic_observation(
        cylinder_object(0.0265, 0.12), (0.6, 0.05, 0.0), rng=np.random.default_rng(4)
    )
    points = TableCluster().segment(observation).points
    # Started 6 deg off the true vertical axis, toward the camera and sideways.
    start = np.array([-math.sin(math.radians(5.0)), math.sin(math.radians(3.3)), 1.0])
    tilted = fit_axis(points, start / np.linalg.norm(start))
    assert tilt_deg(tilted.axis) > 5.5
    settled, share = settled_axis(points, observation, tilted, 0.01, 0.0)
    assert isinstance(settled, AxisFit)
    assert tilt_deg(settled.axis) < 1.5
    assert np.linalg.norm(settled.axis.point_m[:2] - [0.6, 0.05]) < 0.003
    assert share < 0.05
