"""Saving camera images: ``rgb.png``, a colour-mapped ``depth.png`` and raw ``depth.npy``.

``depth.png`` is drawn in image space (:mod:`pipeline.reports.raster`, no display or plotting state
needed); matplotlib (its colour tables) is imported by the functions that draw, so a trial
without pictures never loads it.
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
    """Write a depth image as a colour-mapped PNG (image space, :mod:`pipeline.reports.raster`) with
    pixel axes and a colour bar in metres; pixels without depth (``NaN``) are drawn in
    magenta and named in a legend with their share. Returns the path."""
    from matplotlib.colors import to_rgb

    from pipeline.reports.raster import SMALL, Frame, Sheet, colour_bar, colour_map

    depth = np.asarray(depth_m, dtype=np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth must be an (H, W) image, got shape {depth.shape}")
    height, width = depth.shape
    valid = np.isfinite(depth)
    low, high = (np.min(depth[valid]), np.max(depth[valid])) if valid.any() else (0.0, 1.0)
    high = max(high, low + 1e-6)
    missing = tuple(round(255 * c) for c in to_rgb(MISSING_COLOUR))
    image = colour_map(DEPTH_COLORMAP, depth.ravel(), low, high).reshape(height, width, 3)
    image[~valid] = missing
    # Small images (tests, thumbnails) are enlarged so the axes and labels fit around them.
    zoom = max(1, int(np.ceil(240 / max(min(height, width), 1))))
    image = np.repeat(np.repeat(image, zoom, axis=0), zoom, axis=1)
    left, top = 70, 40
    sheet = Sheet(left + width * zoom + 120, top + height * zoom + 55)
    sheet.paste(image, left, top)
    frame = Frame(left, top, width * zoom, height * zoom, (0.0, width), (height, 0.0))
    frame.axes(sheet, xlabel="column (px)", ylabel="row (px)", title=title)
    colour_bar(
        sheet,
        left + width * zoom + 15,
        top,
        height * zoom,
        DEPTH_COLORMAP,
        low,
        high,
        "depth along the optical axis (m)",
    )
    missing_percent = 100.0 * (1.0 - valid.mean())
    legend = f"no depth ({missing_percent:.1f} %)"
    right, bottom = left + width * zoom - 8, top + height * zoom - 8
    sheet.rectangle(right - 130, bottom - 22, 130, 22, (255, 255, 255))
    sheet.outline(right - 130, bottom - 22, 130, 22, (200, 200, 200))
    sheet.rectangle(right - 124, bottom - 16, 16, 10, missing)
    sheet.text(right - 102, bottom - 11, legend, size=SMALL, anchor="lm")
    return sheet.save(Path(path_png))


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
