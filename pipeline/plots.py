"""Every figure symfuse draws: a trial's pictures and the experiments' study figures.

A trial's pictures (:func:`deviation_heatmap`, :func:`plot_cloud_with_plane`,
:func:`plot_vc_scores`; ``depth.png`` in :mod:`pipeline.images`) are drawn in image space
(:mod:`pipeline.raster`): a trial draws them every time, and matplotlib's axes and markers
cost several times the drawing itself. The experiments' figures (histograms, error grids,
box plots) and the multi-object scene picture use matplotlib's object API with the Agg
canvas: no pyplot, no global backend switch, so they work headless, in worker processes and
beside a user's own backend; matplotlib is imported by the functions that use it. Inputs are
in SI units (metres, radians); the figures print millimetres and degrees.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .images import PNG_OPTIONS
from .raster import SMALL, Frame, Sheet, colour_bar, colour_map

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from .types import SymmetryHypothesis, SymmetryPlane

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


def _save(figure: Figure, out_path: Path) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(figure)
    figure.savefig(out_path, dpi=120, pil_kwargs=PNG_OPTIONS)
    return out_path


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


def deviation_histogram(
    panels: Sequence[DeviationPanel],
    out_path: Path,
    *,
    max_deviation_m: float = DEVIATION_MAX_M,
    bins: int = 30,
    title: str = "",
) -> Path:
    """Overlaid histograms of the deviations of several completed clouds (mm); deviations
    beyond ``max_deviation_m`` are counted in the last bin."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(6.0, 4.0), layout="constrained")
    ax = figure.subplots()
    edges = np.linspace(0.0, max_deviation_m * 1e3, bins + 1)
    for panel in panels:
        values = np.clip(np.asarray(panel.distances_m) * 1e3, 0.0, edges[-1])
        ax.hist(values, bins=edges, histtype="step", linewidth=1.5, label=panel.label)
    ax.set_xlabel("deviation (mm)")
    ax.set_ylabel("points")
    ax.legend()
    if title:
        ax.set_title(title)
    return _save(figure, out_path)


@dataclass(frozen=True)
class GridPanel:
    """An error map over a 2-D grid: ``values[i, j]`` at ``(x_values[j], y_values[i])``."""

    title: str
    x_values: np.ndarray
    y_values: np.ndarray
    values: np.ndarray


def _edges(centres: np.ndarray) -> np.ndarray:
    centres = np.asarray(centres, dtype=np.float64)
    if len(centres) == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    middle = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([[2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]])


def error_grid_figure(
    panels: Sequence[GridPanel],
    out_path: Path,
    *,
    xlabel: str,
    ylabel: str,
    colour_label: str,
    vmax: float,
    threshold: float | None = None,
    title: str = "",
) -> Path:
    """One colour map per panel (the paper's Fig. 8/9 layout), each cell labelled with its
    value; NaN cells (failed runs) are grey. ``threshold`` outlines the cells below it."""
    from matplotlib.figure import Figure

    columns = min(len(panels), 3)
    rows = int(np.ceil(len(panels) / columns))
    figure = Figure(figsize=(4.3 * columns + 1.0, 3.8 * rows), layout="constrained")
    axes = figure.subplots(rows, columns, squeeze=False).reshape(-1)
    mesh = None
    for ax, panel in zip(axes, panels, strict=False):
        values = np.ma.masked_invalid(np.asarray(panel.values, dtype=np.float64))
        ax.set_facecolor("0.6")
        mesh = ax.pcolormesh(
            _edges(panel.x_values),
            _edges(panel.y_values),
            values,
            cmap="viridis",
            vmin=0.0,
            vmax=vmax,
        )
        x_edges, y_edges = _edges(panel.x_values), _edges(panel.y_values)
        for i, j in np.ndindex(values.shape):
            if not np.ma.is_masked(values[i, j]):
                ax.text(
                    0.5 * (x_edges[j] + x_edges[j + 1]),
                    0.5 * (y_edges[i] + y_edges[i + 1]),
                    f"{values[i, j]:.0f}",
                    ha="center",
                    va="center",
                    fontsize=6,
                    color="white" if values[i, j] < 0.6 * vmax else "black",
                )
        if threshold is not None:
            good = np.asarray(panel.values) < threshold
            for i, j in zip(*np.nonzero(good), strict=True):
                x = _edges(panel.x_values)[j : j + 2]
                y = _edges(panel.y_values)[i : i + 2]
                ax.plot(
                    [x[0], x[1], x[1], x[0], x[0]],
                    [y[0], y[0], y[1], y[1], y[0]],
                    color="white",
                    linewidth=0.6,
                )
        ax.set_title(panel.title)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    if mesh is not None:
        figure.colorbar(mesh, ax=list(axes[: len(panels)]), label=colour_label, shrink=0.9)
    if title:
        figure.suptitle(title)
    return _save(figure, out_path)


@dataclass(frozen=True)
class BoxPanel:
    """Box plots of samples per category: ``samples[k]`` at ``positions[k]``."""

    title: str
    positions: np.ndarray
    samples: Sequence[np.ndarray]


def box_plot_figure(
    panels: Sequence[BoxPanel],
    out_path: Path,
    *,
    xlabel: str,
    ylabel: str,
    threshold: float | None = None,
    ylim: tuple[float, float] | None = None,
    title: str = "",
) -> Path:
    """Box-and-whisker plots (quartiles, whiskers at min and max) per panel (the paper's
    Fig. 10 layout); ``threshold`` draws a dashed horizontal reference line."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(5.5 * len(panels), 4.2), layout="constrained")
    axes = figure.subplots(1, len(panels), squeeze=False)[0]
    for ax, panel in zip(axes, panels, strict=True):
        positions = np.asarray(panel.positions, dtype=np.float64)
        width = 0.6 * (np.min(np.diff(positions)) if len(positions) > 1 else 1.0)
        ax.boxplot(
            [np.asarray(s, dtype=np.float64) for s in panel.samples],
            positions=positions,
            widths=width,
            whis=(0, 100),
            manage_ticks=False,
        )
        ax.set_xticks(positions)
        ax.set_xticklabels([f"{p:g}" for p in positions])
        if threshold is not None:
            ax.axhline(threshold, color="tab:red", linestyle="--", linewidth=1)
        if ylim is not None:
            ax.set_ylim(*ylim)
        ax.set_title(panel.title)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
    if title:
        figure.suptitle(title)
    return _save(figure, out_path)


@dataclass(frozen=True)
class SceneObjectView:
    """What the scene picture shows of one object: its number, its pixels (rows, cols),
    its visible points and, once completed, the completed model and symmetry plane (frame R).
    """

    index: int
    pixels: np.ndarray
    points_robot: np.ndarray
    completed_robot: np.ndarray | None = None
    plane: SymmetryPlane | None = None


def plot_scene(
    image: np.ndarray,
    objects: Sequence[SceneObjectView],
    path: Path,
    *,
    title: str = "",
) -> Path:
    """Left: the ``(H, W, 3)`` image with each object outlined and numbered. Right: the
    robot frame from above (mm) with each object's visible points, its completed footprint
    and the trace of its symmetry plane."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    mm = 1000.0
    height, width = image.shape[:2]
    figure = Figure(figsize=(14, 6))
    FigureCanvasAgg(figure)
    left, right = figure.subplots(1, 2)
    left.imshow(image, interpolation="nearest")
    colours = matplotlib.colormaps["tab10"]
    for view in objects:
        colour = colours(view.index % 10)
        mask = np.zeros((height, width), dtype=float)
        mask[view.pixels[:, 0], view.pixels[:, 1]] = 1.0
        left.contour(mask, levels=[0.5], colors=[colour], linewidths=1.5)
        row, col = view.pixels.mean(axis=0)
        left.text(
            col,
            row,
            str(view.index),
            color="white",
            fontsize=14,
            weight="bold",
            ha="center",
            va="center",
            bbox={"facecolor": colour, "alpha": 0.8},
        )
        shown = view.completed_robot if view.completed_robot is not None else view.points_robot
        right.scatter(shown[:, 0] * mm, shown[:, 1] * mm, s=0.5, color=colour, alpha=0.25)
        right.scatter(
            view.points_robot[:, 0] * mm, view.points_robot[:, 1] * mm, s=0.5, color=colour
        )
        centre = shown[:, :2].mean(axis=0)
        right.text(
            centre[0] * mm,
            centre[1] * mm,
            str(view.index),
            fontsize=12,
            weight="bold",
            ha="center",
            va="center",
        )
        if view.plane is not None:
            normal = view.plane.normal[:2]
            foot = centre - (centre @ normal - view.plane.offset_m) * normal
            half = 0.6 * float(np.ptp(shown[:, :2], axis=0).max())
            ends = foot + np.outer([-half, half], [-normal[1], normal[0]])
            right.plot(ends[:, 0] * mm, ends[:, 1] * mm, "-", color="red", linewidth=1.5)
    left.set_title("segmented objects")
    left.set_axis_off()
    right.set_aspect("equal")
    right.set_xlabel("x (mm)")
    right.set_ylabel("y (mm)")
    right.set_title("from above: visible points, completed footprint (faint), symmetry plane")
    if title:
        figure.suptitle(title)
    path = Path(path)
    figure.savefig(path, dpi=110, bbox_inches="tight", pil_kwargs=PNG_OPTIONS)
    return path


@dataclass(frozen=True)
class GraspMarks:
    """One grasp's taxels in contact for :func:`grasps_figure`: their ``(M, 3)`` positions
    (frame R, m), the pad of each, and the legend text (e.g. the deviation after it)."""

    label: str
    taxels_m: np.ndarray
    pads: np.ndarray


def grasps_figure(
    out_path: Path,
    model_m: np.ndarray,
    truth_vertices_m: np.ndarray,
    grasps: Sequence[GraspMarks],
    title: str,
) -> Path:
    """The object from above: the true footprint (the convex hull of the mesh, grey), the
    final completed model (blue), and each grasp's taxels in contact in its own colour,
    every pad numbered with its grasp at the centroid of its taxels; the legend carries
    each grasp's label. Axes in mm, frame R."""
    from matplotlib.figure import Figure
    from scipy.spatial import ConvexHull

    figure = Figure(figsize=(6.4, 6.0), dpi=110)
    axes = figure.add_subplot(1, 1, 1)

    truth = 1e3 * np.asarray(truth_vertices_m)[:, :2]
    outline = truth[ConvexHull(truth).vertices]
    axes.fill(*outline.T, fc="0.9", ec="0.5", label="true footprint (hull)")
    model = 1e3 * np.asarray(model_m)[:, :2]
    axes.scatter(*model.T, s=1, c="tab:blue", alpha=0.4, label="final model")
    colours = ("tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink")
    for number, grasp in enumerate(grasps, start=1):
        colour = colours[(number - 1) % len(colours)]
        taxels = 1e3 * np.asarray(grasp.taxels_m)[:, :2]
        axes.scatter(*taxels.T, s=10, c=colour, marker="s", label=f"{number}: {grasp.label}")
        for pad in np.unique(grasp.pads):
            centre = taxels[grasp.pads == pad].mean(axis=0)
            axes.annotate(
                str(number),
                centre,
                fontsize=11,
                fontweight="bold",
                color="white",
                ha="center",
                va="center",
                bbox={"boxstyle": "circle,pad=0.2", "fc": colour, "ec": "none"},
            )
    axes.set_aspect("equal")
    axes.set_xlabel("x (mm)")
    axes.set_ylabel("y (mm)")
    axes.set_title(title)
    axes.legend(loc="best", fontsize=8, markerscale=2)
    figure.tight_layout()
    return _save(figure, out_path)


@dataclass(frozen=True)
class LinePanel:
    """One panel of :func:`line_figure`: a curve per label over the same ``x``."""

    title: str
    x_label: str
    y_label: str
    x: Sequence[float]
    curves: dict[str, Sequence[float]]


def line_figure(panels: Sequence[LinePanel], out_path: Path, title: str) -> Path:
    """Panels side by side, each with one marked line per curve (NaN points left out)."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(4.8 * len(panels), 4.0), dpi=110)
    for index, panel in enumerate(panels, start=1):
        axes = figure.add_subplot(1, len(panels), index)
        for label, values in panel.curves.items():
            axes.plot(panel.x, values, marker="o", label=label)
        axes.set_xticks(list(panel.x))
        axes.set_xlabel(panel.x_label)
        axes.set_ylabel(panel.y_label)
        axes.set_title(panel.title, fontsize=10)
        axes.set_ylim(bottom=0.0)
        axes.grid(alpha=0.3)
        axes.legend(fontsize=8)
    figure.suptitle(title)
    figure.tight_layout()
    return _save(figure, out_path)
