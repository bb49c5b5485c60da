"""The figures drawn with matplotlib: the experiments' study figures (deviation
histograms, error grids, box plots, line panels) and the multi-object scene picture.

They use matplotlib's object API with the Agg canvas: no pyplot, no global backend switch,
so they work headless, in worker processes and beside a user's own backend; matplotlib is
imported by the functions that use it. Inputs are in SI units (metres, radians); the
figures print millimetres and degrees.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.io.images import PNG_OPTIONS
from pipeline.reports.trial_pictures import DEVIATION_MAX_M, DeviationPanel

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from pipeline.types import SymmetryPlane


def _save(figure: Figure, out_path: Path) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(figure)
    figure.savefig(out_path, dpi=120, pil_kwargs=PNG_OPTIONS)
    return out_path


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
    its visible points, its status and, once completed, the completed model and symmetry
    plane (frame R).
    """

    index: int
    pixels: np.ndarray
    points_robot: np.ndarray
    completed_robot: np.ndarray | None = None
    plane: SymmetryPlane | None = None
    status: str = ""


#: Colour of the clusters set aside in the scene picture.
SET_ASIDE_COLOUR = "0.6"


def plot_scene(
    image: np.ndarray,
    objects: Sequence[SceneObjectView],
    path: Path,
    *,
    title: str = "",
    set_aside: Sequence[tuple[np.ndarray, str]] = (),
) -> Path:
    """Left: the ``(H, W, 3)`` image with each object outlined, numbered and labelled with
    its status, and each cluster set aside (``set_aside``: its pixels and why) outlined in
    grey, dashed, with the reason. Right: the robot frame from above (mm) with each
    object's visible points, its completed footprint and the trace of its symmetry plane."""
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

    def outline(pixels: np.ndarray, label: str, colour, style: str, size: int) -> None:
        mask = np.zeros((height, width), dtype=float)
        mask[pixels[:, 0], pixels[:, 1]] = 1.0
        left.contour(mask, levels=[0.5], colors=[colour], linewidths=1.5, linestyles=style)
        row, col = pixels.mean(axis=0)
        left.text(
            col,
            row,
            label,
            color="white",
            fontsize=size,
            weight="bold",
            ha="center",
            va="center",
            bbox={"facecolor": colour, "alpha": 0.8},
        )

    for pixels, reason in set_aside:
        outline(pixels, f"set aside:\n{reason}", SET_ASIDE_COLOUR, "dashed", 7)
    for view in objects:
        colour = colours(view.index % 10)
        label = f"{view.index}\n{view.status}" if view.status else str(view.index)
        outline(view.pixels, label, colour, "solid", 10 if view.status else 14)
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
    left.set_title("segmented objects and their status; set aside (grey, dashed) and why")
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


@dataclass(frozen=True)
class DotPanel:
    """One panel of :func:`dot_figure`: a marker per series and row, and dashed reference
    lines at ``targets``."""

    x_label: str
    series: dict[str, Sequence[float]]
    targets: Sequence[float] = ()


def dot_figure(
    labels: Sequence[str], panels: Sequence[DotPanel], out_path: Path, title: str
) -> Path:
    """Panels side by side sharing one row per label (top to bottom), each with a marker
    per series (NaN left out): a dot chart of many objects' numbers."""
    from matplotlib.figure import Figure

    rows = np.arange(len(labels))[::-1]
    figure = Figure(figsize=(5.0 * len(panels), 1.2 + 0.28 * len(labels)), layout="constrained")
    axes = figure.subplots(1, len(panels), sharey=True, squeeze=False)[0]
    for ax, panel in zip(axes, panels, strict=True):
        for marker, (name, values) in zip("osD^v", panel.series.items(), strict=False):
            ax.plot(np.asarray(values, dtype=float), rows, marker, label=name, alpha=0.8)
        for target in panel.targets:
            ax.axvline(target, color="tab:red", linestyle="--", linewidth=0.8)
        ax.set_xlabel(panel.x_label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower left")
    axes[0].set_yticks(rows)
    axes[0].set_yticklabels(labels, fontsize=8)
    figure.suptitle(title)
    return _save(figure, out_path)


@dataclass(frozen=True)
class BarGroups:
    """Grouped bars: for each of ``labels``, one bar per series (NaN left out)."""

    labels: Sequence[str]
    series: dict[str, Sequence[float]]
    y_label: str


def bar_figure(groups: BarGroups, out_path: Path, title: str) -> Path:
    """A grouped bar chart, the groups side by side along x, each with its series' bars."""
    from matplotlib.figure import Figure

    x = np.arange(len(groups.labels))
    width = 0.8 / max(1, len(groups.series))
    figure = Figure(figsize=(2.0 + 0.6 * len(groups.labels), 4.0), layout="constrained")
    ax = figure.subplots()
    for k, (name, values) in enumerate(groups.series.items()):
        ax.bar(x + (k - (len(groups.series) - 1) / 2) * width, values, width, label=name)
    ax.set_xticks(x)
    ax.set_xticklabels(groups.labels, rotation=60, ha="right", fontsize=8)
    ax.set_ylabel(groups.y_label)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    figure.suptitle(title)
    return _save(figure, out_path)
