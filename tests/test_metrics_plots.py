"""Deviation pictures and study figures (pipeline.reports.trial_pictures,
pipeline.reports.figures)."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.image import imread

from pipeline.metrics import point_to_mesh_distances
from pipeline.reports.figures import (
    BoxPanel,
    GridPanel,
    box_plot_figure,
    deviation_histogram,
    error_grid_figure,
)
from pipeline.reports.trial_pictures import (
    DeviationPanel,
    deviation_heatmap,
    deviation_scale_m,
    view_projection,
)
from pipeline.synthetic import Cylinder, cylinder_mesh, make_case


def test_view_projection_axes():
    top = view_projection(np.radians(-90.0), np.radians(90.0))
    np.testing.assert_allclose(top @ [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(top @ [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    oblique = view_projection(0.3, 0.6)
    np.testing.assert_allclose(oblique @ oblique.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(oblique) == pytest.approx(1.0)
    # The third row points from the scene toward the viewer.
    toward = [np.cos(0.6) * np.cos(0.3), np.cos(0.6) * np.sin(0.3), np.sin(0.6)]
    np.testing.assert_allclose(oblique[2], toward, atol=1e-12)
    # Screen "up" has a positive world-z component for a view from above.
    assert oblique[1, 2] > 0.0


def test_heatmap_and_histogram_of_three_stages(tmp_path):
    case = make_case(np.random.default_rng(0), theta_error_rad=0.4, r_error_m=0.01)
    vertices, faces = cylinder_mesh(Cylinder())
    panels = []
    for label, plane in (("Stage 0", case.init_plane), ("Stage 2", case.true_plane)):
        completed = np.vstack([case.cloud.points, plane.mirror(case.cloud.points)])
        panels.append(
            DeviationPanel(label, completed, point_to_mesh_distances(completed, vertices, faces))
        )
    assert np.median(panels[0].distances_m) > np.median(panels[1].distances_m)
    top = deviation_heatmap(panels, tmp_path / "top.png", mesh=(vertices, faces))
    oblique = deviation_heatmap(
        panels,
        tmp_path / "sub" / "oblique.png",
        mesh=(vertices, faces),
        elevation_rad=np.radians(35.0),
        title="3/4 view",
    )
    histogram = deviation_histogram(panels, tmp_path / "hist.png")
    for path in (top, oblique, histogram):
        image = imread(path)
        assert image.ndim == 3 and image.shape[0] > 200


def test_deviation_scale_spans_the_worst_panel_rounded_up():
    """The 95th percentile of the worst panel, rounded up to 1, 2 or 5 x 10^k mm."""

    def panel(distances_mm):
        distances = np.asarray(distances_mm, dtype=float) * 1e-3
        return DeviationPanel("p", np.zeros((len(distances), 3)), distances)

    ramp = np.linspace(0.0, 1.0, 101)  # its 95th percentile is 0.95
    assert deviation_scale_m([panel(3.3 / 0.95 * ramp)]) == pytest.approx(0.005)
    assert deviation_scale_m([panel(0.7 / 0.95 * ramp), panel(0.2 * ramp)]) == pytest.approx(0.001)
    assert deviation_scale_m([panel(12.0 / 0.95 * ramp)]) == pytest.approx(0.020)
    assert deviation_scale_m([panel(2.0 / 0.95 * ramp)]) == pytest.approx(0.002)
    assert deviation_scale_m([panel(np.zeros(5))]) == pytest.approx(0.001)


def test_study_figures(tmp_path):
    grid = GridPanel(
        "a",
        np.array([-10.0, 0.0, 10.0]),
        np.array([0.0, 45.0]),
        np.array([[1.0, 2.0, np.nan], [5.0, 30.0, 0.5]]),
    )
    path = error_grid_figure(
        [grid, grid],
        tmp_path / "grid.png",
        xlabel="r",
        ylabel="t",
        colour_label="mm",
        vmax=20.0,
        threshold=4.0,
    )
    assert imread(path).shape[1] > 300
    boxes = BoxPanel("b", np.array([0.0, 5.0]), [np.array([1.0, 2.0, 3.0]), np.array([4.0])])
    path = box_plot_figure([boxes], tmp_path / "box.png", xlabel="x", ylabel="y", threshold=4.0)
    assert imread(path).shape[1] > 300
