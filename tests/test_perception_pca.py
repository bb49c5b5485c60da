"""PCA of a table-projected cloud against the analytic axes of a box."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.perception.principal_axes import pca_plane, table_axes


@pytest.mark.parametrize("yaw", [0.3, 1.2, 2.5, -1.0])
def test_axes_of_a_uniform_box(yaw):
    rng = np.random.default_rng(0)
    local = rng.uniform([-0.1, -0.025, 0.0], [0.1, 0.025, 0.15], size=(200000, 3))
    c, s = np.cos(yaw), np.sin(yaw)
    points = local @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T + [0.5, -0.2, 0.7]
    axes = table_axes(points)
    expected = (yaw + np.pi / 2) % np.pi - np.pi / 2  # the major axis angle in (-pi/2, pi/2]
    assert axes.major_angle_rad == pytest.approx(expected, abs=np.deg2rad(0.3))
    assert abs(axes.major @ axes.minor) < 1e-12 and np.cross(axes.major, axes.minor)[2] > 0
    # Uniform on a length L: variance L^2 / 12.
    np.testing.assert_allclose(axes.variances_m2, [0.2**2 / 12, 0.05**2 / 12], rtol=0.02)
    np.testing.assert_allclose(axes.centroid_m[:2], [0.5, -0.2], atol=1e-3)
    plane = pca_plane(points)
    assert plane.offset_m == pytest.approx(axes.minor[:2] @ [0.5, -0.2], abs=1e-3)
