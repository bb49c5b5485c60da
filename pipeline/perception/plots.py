"""Figures of the perception stage: the cloud from above with a plane, VC scores, and a
scene with every segmented object.

matplotlib with the non-interactive Agg backend; every function writes one PNG and
returns its path.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.types import SymmetryHypothesis, SymmetryPlane


def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_cloud_with_plane(
    points_robot: np.ndarray,
    plane: SymmetryPlane,
    path: Path,
    *,
    title: str = "",
) -> Path:
    """Top-down view (robot x, y in mm) of the cloud coloured by height, its mirror image in
    grey and the plane's trace on the table as a line."""
    from pipeline.images import PNG_OPTIONS
    from pipeline.plots import scatter_subset

    plt = _figure()
    mm = 1000.0
    mirrored = plane.mirror(points_robot)
    shown = scatter_subset(len(points_robot))
    figure, axes = plt.subplots(figsize=(6, 6))
    figure.subplots_adjust(left=0.14, right=0.98, bottom=0.1, top=0.93)
    axes.scatter(mirrored[shown, 0] * mm, mirrored[shown, 1] * mm, s=1, c="0.75", label="mirrored")
    scatter = axes.scatter(
        points_robot[shown, 0] * mm,
        points_robot[shown, 1] * mm,
        s=1,
        c=points_robot[shown, 2] * mm,
    )
    figure.colorbar(scatter, ax=axes, label="height z (mm)")
    both = np.concatenate([points_robot, mirrored])[:, :2]
    span = float(np.ptp(both, axis=0).max()) * 0.75 + 0.02
    normal = plane.normal[:2]
    foot = both.mean(axis=0) - (both.mean(axis=0) @ normal - plane.offset_m) * normal
    along = np.array([-normal[1], normal[0]])
    ends = foot + np.outer([-span, span], along)
    axes.plot(ends[:, 0] * mm, ends[:, 1] * mm, "r-", label="symmetry plane")
    # The axes keep their place and the data limits grow to equal scales (no tight crop).
    axes.set_aspect("equal", adjustable="datalim")
    axes.set_xlabel("x (mm)")
    axes.set_ylabel("y (mm)")
    axes.set_title(
        title
        or f"plane: theta {np.rad2deg(plane.theta_rad):.1f} deg, "
        f"offset {plane.offset_m * mm:.1f} mm"
    )
    # Below the axes, where it never hides points (the cloud may fill any corner).
    axes.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, markerscale=8)
    path = Path(path)
    figure.savefig(path, dpi=120, pil_kwargs=PNG_OPTIONS)
    plt.close(figure)
    return path


def plot_vc_scores(
    hypotheses: Sequence[SymmetryHypothesis],
    centroid_m: np.ndarray,
    path: Path,
) -> Path:
    """The VC hypothesis grid: normal angle (deg) against offset from the centroid along the
    normal (mm), coloured by the fraction of mirrored points in free space; the winner
    (``hypotheses[0]``) is circled."""
    plt = _figure()
    theta = np.array([h.plane.theta_rad for h in hypotheses])
    relative = np.array(
        [h.plane.offset_m - h.plane.normal[:2] @ np.asarray(centroid_m)[:2] for h in hypotheses]
    )
    score = np.array([h.score for h in hypotheses])
    figure, axes = plt.subplots(figsize=(7, 5))
    scatter = axes.scatter(
        np.rad2deg(theta), relative * 1000.0, c=score, marker="s", s=60, cmap="viridis_r"
    )
    figure.colorbar(scatter, ax=axes, label="fraction of mirrored points in free space")
    axes.scatter(
        np.rad2deg(theta[0]), relative[0] * 1000.0, s=200, facecolors="none", edgecolors="r"
    )
    axes.set_xlabel("plane normal angle theta (deg)")
    axes.set_ylabel("offset from centroid r (mm)")
    axes.set_title(f"VC: {len(hypotheses)} hypotheses, best violates {score[0]:.1%}")
    path = Path(path)
    figure.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(figure)
    return path


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
    plt = _figure()
    mm = 1000.0
    height, width = image.shape[:2]
    figure, (left, right) = plt.subplots(1, 2, figsize=(14, 6))
    left.imshow(image, interpolation="nearest")
    colours = plt.get_cmap("tab10")
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
    figure.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(figure)
    return path
