"""Image-space drawing (pipeline.reports.raster) against independent oracles."""

from __future__ import annotations

import numpy as np
from matplotlib.path import Path as MplPath

from pipeline.reports.raster import Frame, Sheet, nice_ticks


def test_triangles_fill_exactly_the_pixels_whose_centres_are_inside():
    rng = np.random.default_rng(0)
    sheet = Sheet(120, 100)
    frame = Frame(10, 5, 100, 90, (0.0, 1.0), (0.0, 1.0))
    xy = rng.uniform(-0.1, 1.1, (30, 2))
    faces = rng.integers(0, 30, (12, 3))
    frame.triangles(sheet, xy, faces, (0, 0, 0))
    painted = np.all(sheet.pixels == 0, axis=2)
    # Oracle: matplotlib's point-in-polygon test at every pixel centre of the frame.
    rows, columns = np.mgrid[0:100, 0:120]
    centres = np.column_stack([columns.ravel() + 0.5, rows.ravel() + 0.5])
    corners = np.column_stack(frame.to_pixels(xy[:, 0], xy[:, 1]))
    expected = np.zeros(len(centres), dtype=bool)
    for face in faces:
        (ax, ay), (bx, by) = corners[face[1:]] - corners[face[0]]
        if abs(ax * by - ay * bx) > 1e-9:  # matplotlib finds nothing inside a flat one
            expected |= MplPath(corners[face]).contains_points(centres)
    expected &= (centres[:, 0] > 10) & (centres[:, 0] < 110) & (centres[:, 1] > 5)
    expected &= centres[:, 1] < 95
    # Pixel centres exactly on an edge may go either way.
    assert np.count_nonzero(painted.ravel() != expected) <= 0.01 * expected.sum()


def test_nearest_point_shows_where_points_overlap():
    sheet = Sheet(20, 20)
    frame = Frame(0, 0, 20, 20, (0.0, 20.0), (0.0, 20.0))
    colours = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]], dtype=np.uint8)
    # Same spot; the middle one is nearest the viewer (largest depth).
    frame.points(sheet, [10.0] * 3, [10.0] * 3, colours, 2.0, depth=np.array([0.0, 5.0, 1.0]))
    assert tuple(sheet.pixels[9, 10]) == (0, 255, 0)
    frame.points(sheet, [3.0, 3.0], [3.0, 3.0], colours[:2], 1.0)  # no depth: the later
    assert tuple(sheet.pixels[16, 3]) == (0, 255, 0)


def test_nice_ticks():
    np.testing.assert_allclose(nice_ticks(-97.0, 103.0), [-50.0, 0.0, 50.0, 100.0])
    np.testing.assert_allclose(nice_ticks(0.76, 1.74), [0.8, 1.0, 1.2, 1.4, 1.6])
    np.testing.assert_allclose(nice_ticks(480.0, 0.0), [0.0, 100.0, 200.0, 300.0, 400.0])
