"""The pictures a trial draws every time: the deviation heatmap
(:func:`deviation_heatmap`), the cloud with its symmetry plane
(:func:`plot_cloud_with_plane`), the VC hypothesis grid (:func:`plot_vc_scores`) and the
grasps from above (:func:`grasps_picture`); ``depth.png`` is in :mod:`pipeline.io.images`.

They are drawn in image space (:mod:`pipeline.reports.raster`): a trial draws them every time, and
matplotlib's axes and markers cost several times the drawing itself. Inputs are in SI
units (metres, radians); the pictures print millimetres and degrees.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.reports.raster import SMALL, Frame, Sheet, colour_bar, colour_map

if TYPE_CHECKING:
    from pipeline.types import SymmetryHypothesis, SymmetryPlane

#: Colour map of deviation pictures (0 blue to the scale's top red) and the paper's fixed
#: 0-30 mm scale, which the histograms keep; the heatmaps scale to their data instead
#: (:func:`deviation_scale_m`), since a fixed 30 mm top shows sub-millimetre change as one
#: shade of blue.
DEVIATION_CMAP = "jet"
DEVIATION_MAX_M = 0.030
#: The share of every panel's points the heatmap colour scale spans.
DEVIATION_SCALE_QUANTILE = 0.95
#: Side of a point panel of a trial picture (px) and the radius of a point in it (px).
PANEL_PX = 360
POINT_RADIUS_PX = 1.2
MESH_GREY = (217, 217, 217)
MIRRORED_GREY = (190, 190, 190)
PLANE_RED = (220, 20, 20)
HEIGHT_CMAP = "viridis"
SCORE_CMAP = "viridis_r"
#: The grasps picture: the true footprint, the final model (light: it lies under the
#: taxels) and one colour per grasp.
FOOTPRINT_GREY = (230, 230, 230)
FOOTPRINT_EDGE = (128, 128, 128)
MODEL_BLUE = (165, 201, 225)
GRASP_COLOURS = (
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
)


@dataclass(frozen=True)
class DeviationPanel:
    """One completed cloud with each point's deviation from the true surface.

    Attributes:
        label: panel title (e.g. ``"Stage 0"``).
        points: ``(N, 3)`` completed cloud, frame ``R``, metres.
        distances_m: ``(N,)`` point-to-mesh distances, metres.
    """

    label: str
    points: np.ndarray
    distances_m: np.ndarray


def view_projection(azimuth_rad: float, elevation_rad: float) -> np.ndarray:
    """``(3, 3)`` rows: screen right, screen up, toward the viewer, for an orthographic view
    from direction (azimuth about +z, elevation above the table). Elevation 90 deg is the
    top-down view with +x to the right and +y up."""
    toward = np.array(
        [
            np.cos(elevation_rad) * np.cos(azimuth_rad),
            np.cos(elevation_rad) * np.sin(azimuth_rad),
            np.sin(elevation_rad),
        ]
    )
    if np.isclose(abs(toward[2]), 1.0):
        right = np.array([1.0, 0.0, 0.0]) if toward[2] > 0 else np.array([-1.0, 0.0, 0.0])
    else:
        right = np.cross([0.0, 0.0, 1.0], toward)
        right /= np.linalg.norm(right)
    up = np.cross(toward, right)
    return np.vstack([right, up, toward])


def deviation_scale_m(panels: Sequence[DeviationPanel]) -> float:
    """The top of a heatmap's colour scale (m): the largest of the panels'
    :data:`DEVIATION_SCALE_QUANTILE` deviations, rounded up to 1, 2 or 5 x 10^k mm, so that
    the panel with the largest errors spans the colours and the others compare with it."""
    largest_mm = max(
        float(np.quantile(np.asarray(panel.distances_m), DEVIATION_SCALE_QUANTILE)) * 1e3
        for panel in panels
    )
    if not np.isfinite(largest_mm) or largest_mm <= 0.0:
        return 1e-3
    decade = 10.0 ** np.floor(np.log10(largest_mm))
    step = next(s for s in (1.0, 2.0, 5.0, 10.0) if s * decade >= largest_mm * (1 - 1e-9))
    return float(step * decade) * 1e-3


def _padded(low: np.ndarray, high: np.ndarray, fraction: float = 0.05):
    """``(x_range, y_range)`` of a 2-D box widened by ``fraction`` of its larger side."""
    pad = fraction * float(np.max(high - low)) + 1e-9
    return (low[0] - pad, high[0] + pad), (low[1] - pad, high[1] + pad)


def deviation_heatmap(
    panels: Sequence[DeviationPanel],
    out_path: Path,
    *,
    mesh: tuple[np.ndarray, np.ndarray] | None = None,
    azimuth_rad: float = np.radians(-60.0),
    elevation_rad: float = np.radians(90.0),
    max_deviation_m: float | None = None,
    title: str = "",
) -> Path:
    """Completed clouds side by side, coloured by deviation (0 blue to ``max`` red).

    Each panel is an orthographic view (default top-down; e.g. elevation 35 deg for a
    3/4 view), all at the same scale and over the same area (mm on the axes). The
    ground-truth mesh, when given as ``(vertices, faces)``, is drawn as its grey silhouette
    behind the points; nearer points are drawn over farther ones. The colour scale's top is
    ``max_deviation_m`` (default :func:`deviation_scale_m`, the same for every panel) and the
    title says it.

    Returns:
        The path written.
    """
    if max_deviation_m is None:
        max_deviation_m = deviation_scale_m(panels)
    scale = f"colours 0 to {max_deviation_m * 1e3:g} mm"
    title = f"{title}; {scale}" if title else scale
    projection = view_projection(azimuth_rad, elevation_rad) * 1e3  # to mm on screen
    screens = [np.asarray(panel.points) @ projection.T for panel in panels]
    mesh_screen = None if mesh is None else np.asarray(mesh[0]) @ projection.T
    shown = [screen[:, :2] for screen in screens if len(screen)]
    if mesh_screen is not None:
        shown.append(mesh_screen[:, :2])
    every = np.vstack(shown) if shown else np.zeros((1, 2))
    x_range, y_range = _padded(every.min(axis=0), every.max(axis=0))
    left, top, gap = 70, 90, 70
    sheet = Sheet(left + len(panels) * (PANEL_PX + gap) + 90, top + PANEL_PX + 60)
    sheet.text(sheet.width / 2, 12, title, anchor="mt")
    for k, (panel, screen) in enumerate(zip(panels, screens, strict=True)):
        frame = Frame.fitted(x_range, y_range, left + k * (PANEL_PX + gap), top, PANEL_PX, PANEL_PX)
        if mesh_screen is not None:
            frame.triangles(sheet, mesh_screen[:, :2], mesh[1], MESH_GREY)
        distances_mm = np.asarray(panel.distances_m) * 1e3
        colours = colour_map(DEVIATION_CMAP, distances_mm, 0.0, max_deviation_m * 1e3)
        frame.points(
            sheet, screen[:, 0], screen[:, 1], colours, POINT_RADIUS_PX, depth=screen[:, 2]
        )
        median_mm = float(np.median(panel.distances_m)) * 1e3
        frame.axes(sheet, xlabel="mm", title=f"{panel.label}\nmedian {median_mm:.1f} mm")
    colour_bar(
        sheet,
        left + len(panels) * (PANEL_PX + gap) - gap + 30,
        top + 30,
        PANEL_PX - 60,
        DEVIATION_CMAP,
        0.0,
        max_deviation_m * 1e3,
        "deviation (mm)",
        beyond_high=True,
    )
    return sheet.save(out_path)


def plot_cloud_with_plane(
    points_robot: np.ndarray,
    plane: SymmetryPlane,
    path: Path,
    *,
    title: str = "",
) -> Path:
    """Top-down view (robot x, y in mm) of the cloud coloured by height, its mirror image in
    grey and the plane's trace on the table as a red line."""
    mm = 1000.0
    points = np.asarray(points_robot, dtype=float)
    mirrored = plane.mirror(points)
    both = np.concatenate([points, mirrored])[:, :2]
    centre = both.mean(axis=0)
    half = 0.5 * float(np.ptp(both, axis=0).max()) * 1.3 + 0.01
    x_range = ((centre[0] - half) * mm, (centre[0] + half) * mm)
    y_range = ((centre[1] - half) * mm, (centre[1] + half) * mm)
    sheet = Sheet(560, 560)
    frame = Frame.fitted(x_range, y_range, 80, 50, 380, 380)
    frame.points(sheet, mirrored[:, 0] * mm, mirrored[:, 1] * mm, MIRRORED_GREY, 1.0)
    heights_mm = points[:, 2] * mm
    low, high = (float(heights_mm.min()), float(heights_mm.max())) if len(points) else (0.0, 1.0)
    high = max(high, low + 1e-6)
    colours = colour_map(HEIGHT_CMAP, heights_mm, low, high)
    frame.points(sheet, points[:, 0] * mm, points[:, 1] * mm, colours, 1.0, depth=heights_mm)
    normal = plane.normal[:2]
    foot = centre - (centre @ normal - plane.offset_m) * normal
    along = np.array([-normal[1], normal[0]])
    ends = (foot + np.outer([-2.0 * half, 2.0 * half], along)) * mm
    frame.line(sheet, ends[0], ends[1], PLANE_RED, 2.0)
    frame.axes(
        sheet,
        xlabel="x (mm)",
        ylabel="y (mm)",
        title=title
        or f"plane: theta {np.rad2deg(plane.theta_rad):.1f} deg, "
        f"offset {plane.offset_m * mm:.1f} mm",
    )
    colour_bar(sheet, 480, 50, 380, HEIGHT_CMAP, low, high, "height z (mm)")
    # The legend below the axes, where it never hides points.
    legend_y = 50 + 380 + 52
    sheet.rectangle(150, legend_y - 5, 10, 10, MIRRORED_GREY)
    sheet.text(166, legend_y, "mirrored", size=SMALL, anchor="lm")
    sheet.rectangle(260, legend_y - 1, 22, 3, PLANE_RED)
    sheet.text(288, legend_y, "symmetry plane", size=SMALL, anchor="lm")
    return sheet.save(path)


def plot_vc_scores(
    hypotheses: Sequence[SymmetryHypothesis],
    centroid_m: np.ndarray,
    path: Path,
) -> Path:
    """The VC hypothesis grid: normal angle (deg) against offset from the centroid along the
    normal (mm), coloured by the fraction of mirrored points in free space; the winner
    (``hypotheses[0]``) is circled in red."""
    theta_deg = np.rad2deg([h.plane.theta_rad for h in hypotheses])
    relative_mm = 1e3 * np.array(
        [h.plane.offset_m - h.plane.normal[:2] @ np.asarray(centroid_m)[:2] for h in hypotheses]
    )
    score = np.array([h.score for h in hypotheses])
    sheet = Sheet(640, 460)
    low = np.array([theta_deg.min(), relative_mm.min()])
    high = np.array([theta_deg.max(), relative_mm.max()])
    frame = Frame(80, 50, 440, 340, *_padded(low, high, 0.06))
    # Each hypothesis a disc filling about its share of the grid: half the median distance
    # (px) to its nearest neighbour.
    at = np.column_stack(frame.to_pixels(theta_deg, relative_mm))
    gaps = np.linalg.norm(at[:, None] - at[None], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    nearest = float(np.median(gaps.min(axis=1))) if len(at) > 1 else 20.0
    radius = float(np.clip(0.45 * nearest, 2.0, 12.0))
    colours = colour_map(SCORE_CMAP, score, float(score.min()), max(float(score.max()), 1e-9))
    frame.points(sheet, theta_deg, relative_mm, colours, radius_px=radius)
    ring = np.linspace(0.0, 2.0 * np.pi, 200)
    (x0, x1), (y0, y1) = frame.x_range, frame.y_range
    ring_x = theta_deg[0] + (radius + 5.0) * np.cos(ring) * (x1 - x0) / frame.width
    ring_y = relative_mm[0] + (radius + 5.0) * np.sin(ring) * (y1 - y0) / frame.height
    frame.points(sheet, ring_x, ring_y, PLANE_RED, 1.0)
    frame.axes(
        sheet,
        xlabel="plane normal angle theta (deg)",
        ylabel="offset from centroid r (mm)",
        title=f"VC: {len(hypotheses)} hypotheses, best violates {score[0]:.1%}",
    )
    colour_bar(
        sheet,
        545,
        50,
        340,
        SCORE_CMAP,
        float(score.min()),
        max(float(score.max()), float(score.min()) + 1e-9),
        "fraction of mirrored points in free space",
    )
    return sheet.save(path)


@dataclass(frozen=True)
class GraspMarks:
    """One grasp's taxels in contact for :func:`grasps_picture`: their ``(M, 3)`` positions
    (frame R, m), the pad of each, and the legend text (e.g. the deviation after it). A
    grasp that was not fused (``fused`` False: it touched one side only or nothing) is
    marked where its plan predicted its pads' contacts instead, with crosses."""

    label: str
    taxels_m: np.ndarray
    pads: np.ndarray
    fused: bool = True


def grasps_picture(
    out_path: Path,
    model_m: np.ndarray,
    truth_vertices_m: np.ndarray,
    grasps: Sequence[GraspMarks],
    title: str,
) -> Path:
    """The object from above: the true footprint (the convex hull of the mesh, grey), the
    final completed model (light blue), and each grasp's taxels in contact in its own colour,
    every pad numbered with its grasp at the centroid of its taxels (a grasp not fused: its
    planned contacts, crossed); the legend below carries each grasp's label. Axes in mm,
    frame R."""
    from scipy.spatial import ConvexHull

    mm = 1000.0
    truth = mm * np.asarray(truth_vertices_m, dtype=float)[:, :2]
    outline = truth[ConvexHull(truth).vertices]  # counter-clockwise
    model = mm * np.asarray(model_m, dtype=float)[:, :2]
    taxels = [mm * np.asarray(g.taxels_m, dtype=float).reshape(-1, 3)[:, :2] for g in grasps]
    shown = np.concatenate([outline, model, *taxels])
    low, high = shown.min(axis=0), shown.max(axis=0)
    legend = ["true footprint (hull)", "final model"]
    legend += [f"{number}: {g.label}" for number, g in enumerate(grasps, start=1)]
    sheet = Sheet(560, 560 + 18 * len(legend))
    frame = Frame.fitted(*_padded(low, high), 80, 50, 440, 440)
    fan = np.column_stack(
        [
            np.zeros(len(outline) - 2, int),
            np.arange(1, len(outline) - 1),
            np.arange(2, len(outline)),
        ]
    )
    frame.triangles(sheet, outline, fan, FOOTPRINT_GREY)
    for start, end in zip(outline, np.roll(outline, -1, axis=0), strict=True):
        frame.line(sheet, start, end, FOOTPRINT_EDGE, 1.0)
    frame.points(sheet, model[:, 0], model[:, 1], MODEL_BLUE, 1.0)
    # A cross's arm: 3 px in data units (the frame has one scale on both axes).
    arm = 3.0 * (frame.x_range[1] - frame.x_range[0]) / frame.width
    for number, (grasp, at) in enumerate(zip(grasps, taxels, strict=True), start=1):
        colour = GRASP_COLOURS[(number - 1) % len(GRASP_COLOURS)]
        if grasp.fused:
            frame.points(sheet, at[:, 0], at[:, 1], colour, 2.0)
        else:
            for x, y in at:
                frame.line(sheet, (x - arm, y - arm), (x + arm, y + arm), colour, 1.5)
                frame.line(sheet, (x - arm, y + arm), (x + arm, y - arm), colour, 1.5)
        pads = np.asarray(grasp.pads)
        for pad in np.unique(pads):
            centre = at[pads == pad].mean(axis=0)
            frame.points(sheet, centre[:1], centre[1:], colour, 9.0)
            column, row = frame.to_pixels(centre[0], centre[1])
            sheet.text(
                float(column),
                float(row),
                str(number),
                size=SMALL,
                anchor="mm",
                colour=(255, 255, 255),
            )
    frame.axes(sheet, xlabel="x (mm)", ylabel="y (mm)", title=title)
    swatches = [
        FOOTPRINT_GREY,
        MODEL_BLUE,
        *(GRASP_COLOURS[k % len(GRASP_COLOURS)] for k in range(len(grasps))),
    ]
    for k, (text, colour) in enumerate(zip(legend, swatches, strict=True)):
        y = 50 + 440 + 50 + 18 * k
        sheet.rectangle(80, y - 5, 10, 10, colour)
        sheet.text(96, y, text, size=SMALL, anchor="lm")
    return sheet.save(out_path)
