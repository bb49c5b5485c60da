"""Saving camera images: ``rgb.png``, a colour-mapped ``depth.png`` and raw ``depth.npy``.

Plots are drawn on a standalone matplotlib ``Figure`` with the Agg canvas (no pyplot state,
no display needed). matplotlib is imported by the functions that draw, so a trial without
pictures never loads it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.types import DepthObservation

#: Colour of pixels without a depth value in ``depth.png``.
MISSING_COLOUR = "magenta"
DEPTH_COLORMAP = "viridis"
#: zlib level for PNGs: 1 writes several times faster than the default 6, files ~30 % larger.
PNG_OPTIONS = {"compress_level": 1}


def save_rgb(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an ``(H, W, 3) uint8`` colour image as PNG; return the path."""
    import matplotlib.image

    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"rgb must be an (H, W, 3) uint8 image, got {rgb.shape} {rgb.dtype}")
    path = Path(path)
    matplotlib.image.imsave(path, rgb, pil_kwargs=PNG_OPTIONS)
    return path


def save_depth(path_png: str | Path, depth_m: np.ndarray, title: str = "depth") -> Path:
    """Write a depth image as a colour-mapped PNG with a colourbar in metres; pixels
    without depth (``NaN``) are drawn in magenta and named in a legend. Returns the path."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    depth = np.asarray(depth_m, dtype=np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth must be an (H, W) image, got shape {depth.shape}")
    height, width = depth.shape
    figure = Figure(figsize=(width / 100 + 2.0, height / 100 + 0.8), dpi=100)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    colormap = matplotlib.colormaps[DEPTH_COLORMAP].with_extremes(bad=MISSING_COLOUR)
    valid = np.isfinite(depth)
    low, high = (np.min(depth[valid]), np.max(depth[valid])) if valid.any() else (0.0, 1.0)
    image = axes.imshow(
        np.ma.masked_invalid(depth),
        cmap=colormap,
        vmin=low,
        vmax=max(high, low + 1e-6),
        interpolation="nearest",
    )
    colourbar = figure.colorbar(image, ax=axes, fraction=0.046, pad=0.03)
    colourbar.set_label("depth along the optical axis (m)")
    missing_percent = 100.0 * (1.0 - valid.mean())
    axes.legend(
        handles=[Patch(color=MISSING_COLOUR, label=f"no depth ({missing_percent:.1f} %)")],
        loc="lower right",
        fontsize="small",
    )
    axes.set_title(title)
    axes.set_xlabel("column (px)")
    axes.set_ylabel("row (px)")
    path = Path(path_png)
    figure.savefig(path, pil_kwargs=PNG_OPTIONS)
    return path


def save_depth_npy(path: str | Path, depth_m: np.ndarray) -> Path:
    """Write the depth image (m, ``NaN`` where missing) as a ``float32`` ``.npy``."""
    path = Path(path)
    np.save(path, np.asarray(depth_m, dtype=np.float32))
    return path


def save_observation(directory: str | Path, observation: DepthObservation) -> list[Path]:
    """Write ``rgb.png``, ``depth.png`` and ``depth.npy`` of an observation into
    ``directory`` (created if needed); return the paths written."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    return [
        save_rgb(directory / "rgb.png", observation.rgb),
        save_depth(directory / "depth.png", observation.depth_m),
        save_depth_npy(directory / "depth.npy", observation.depth_m),
    ]
