"""Figures: deviation heatmaps and histograms of completed clouds, and the synthetic studies'
error maps and box plots.

Uses matplotlib's object API with the Agg canvas (no pyplot, no global backend switch), so
it works headless and in worker processes. Inputs are in SI units (metres, radians); the
figures print millimetres and degrees.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from .images import PNG_OPTIONS

#: Colour map of deviation pictures (0 blue to the scale's top red) and the paper's fixed
#: 0-30 mm scale, which the histograms keep; the heatmaps scale to their data instead
#: (:func:`deviation_scale_m`), since a fixed 30 mm top shows sub-millimetre change as one
#: shade of blue.
DEVIATION_CMAP = "jet"
DEVIATION_MAX_M = 0.030
#: The share of every panel's points the heatmap colour scale spans.
DEVIATION_SCALE_QUANTILE = 0.95
#: Points a scatter panel draws at most. Beyond that a fixed random subset is drawn: at
#: these figure sizes it looks the same, and matplotlib's time grows with every marker.
SCATTER_POINTS = 4000


def scatter_subset(count: int, limit: int = SCATTER_POINTS) -> np.ndarray:
    """Sorted indices of at most ``limit`` of ``count`` points (the same on every call)."""
    if count <= limit:
        return np.arange(count)
    return np.sort(np.random.default_rng(0).choice(count, limit, replace=False))


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
    3/4 view). The ground-truth mesh, when given as ``(vertices, faces)``, is drawn as its
    grey silhouette behind the points; nearer points are drawn over farther ones. The
    colour scale's top is ``max_deviation_m`` (default :func:`deviation_scale_m`, the same
    for every panel) and the title says it.

    Returns:
        The path written.
    """
    if max_deviation_m is None:
        max_deviation_m = deviation_scale_m(panels)
    scale = f"colours 0 to {max_deviation_m * 1e3:g} mm"
    title = f"{title}; {scale}" if title else scale
    projection = view_projection(azimuth_rad, elevation_rad)
    # Fixed margins: a constrained layout measures every label first, which costs more than
    # drawing the figure.
    figure = Figure(figsize=(4.2 * len(panels) + 1.0, 4.4))
    figure.subplots_adjust(left=0.05, right=0.97, bottom=0.12, top=0.8, wspace=0.25)
    axes = figure.subplots(1, len(panels), squeeze=False)[0]
    scatter = None
    for ax, panel in zip(axes, panels, strict=True):
        if mesh is not None:
            vertices, faces = mesh
            screen = (np.asarray(vertices) @ projection.T)[:, :2] * 1e3
            ax.add_collection(
                PolyCollection(
                    screen[np.asarray(faces)], facecolors="0.85", edgecolors="none", zorder=0
                )
            )
        shown = scatter_subset(len(panel.points))
        screen_points = np.asarray(panel.points)[shown] @ projection.T
        order = np.argsort(screen_points[:, 2])
        scatter = ax.scatter(
            screen_points[order, 0] * 1e3,
            screen_points[order, 1] * 1e3,
            c=np.asarray(panel.distances_m)[shown][order] * 1e3,
            cmap=DEVIATION_CMAP,
            vmin=0.0,
            vmax=max_deviation_m * 1e3,
            s=2,
            linewidths=0,
            zorder=1,
        )
        median_mm = float(np.median(panel.distances_m)) * 1e3
        ax.set_title(f"{panel.label}\nmedian {median_mm:.1f} mm")
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel("mm")
    if scatter is not None:
        figure.colorbar(scatter, ax=list(axes), label="deviation (mm)", shrink=0.85, extend="max")
    figure.suptitle(title)
    return _save(figure, out_path)


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
    figure = Figure(figsize=(6.4, 6.0), dpi=110)
    axes = figure.add_subplot(1, 1, 1)
    from scipy.spatial import ConvexHull

    truth = 1e3 * np.asarray(truth_vertices_m)[:, :2]
    outline = truth[ConvexHull(truth).vertices]
    axes.fill(*outline.T, fc="0.9", ec="0.5", label="true footprint (hull)")
    model = 1e3 * np.asarray(model_m)[:, :2]
    shown = scatter_subset(len(model))
    axes.scatter(*model[shown].T, s=1, c="tab:blue", alpha=0.4, label="final model")
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
