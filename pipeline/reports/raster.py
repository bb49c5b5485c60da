"""Image-space drawing: points, triangles, lines, axes and text straight into an RGB array.

A trial draws its pictures after every estimate, so they must cost little next to the trial.
Drawn through matplotlib's artists (axes with ticks, a colour bar, one marker per point)
nearly all of a picture's time went into laying out axes and text. Here a picture is a
numpy image: points are splatted as small discs of pixels, the one nearest the viewer on
top; a mesh's silhouette is its triangles scan-converted; lines are dense rows of dots;
text comes from Pillow's built-in scalable font; axes get ticks at 1-2-5 steps. Colour maps
are matplotlib's (its tables only, no figure).

Coordinates: a :class:`Frame` maps data ``(x, y)`` (y up) onto a rectangle of the
:class:`Sheet` (pixel columns right, rows down).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.io.images import PNG_OPTIONS

WHITE = (255, 255, 255)
BLACK = (0, 0, 0)
#: Text sizes (px): tick labels and legends, axis labels and titles.
SMALL, NORMAL = 12, 14


@functools.cache
def _font(size: int):
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


def colour_map(name: str, values: np.ndarray, low: float, high: float) -> np.ndarray:
    """``(N, 3) uint8`` colours of ``values`` under matplotlib's colour map ``name``, scaled
    so that ``low`` is the map's first and ``high`` its last colour (clipped beyond)."""
    import matplotlib

    table = (matplotlib.colormaps[name](np.linspace(0.0, 1.0, 256))[:, :3] * 255).round()
    scaled = (np.asarray(values, dtype=float) - low) / max(high - low, 1e-300)
    index = np.clip(np.nan_to_num(scaled, nan=0.0) * 255.0 + 0.5, 0, 255).astype(np.intp)
    return table.astype(np.uint8)[index]


def nice_ticks(low: float, high: float, count: int = 5) -> np.ndarray:
    """About ``count`` tick values at a 1, 2 or 5 x 10^k step inside ``[low, high]``."""
    low, high = min(low, high), max(low, high)
    span = high - low
    if not np.isfinite(span) or span <= 0.0:
        return np.array([low])
    raw = span / count
    decade = 10.0 ** np.floor(np.log10(raw))
    step = next(s * decade for s in (1.0, 2.0, 5.0, 10.0) if s * decade >= raw)
    first = np.ceil(low / step - 1e-9) * step
    ticks = np.arange(first, high + 1e-9 * step, step)
    return np.where(np.abs(ticks) < 1e-9 * step, 0.0, ticks)


def tick_label(value: float) -> str:
    return f"{value:g}"


class Sheet:
    """A white RGB picture being drawn on.

    Attributes:
        pixels: ``(height, width, 3) uint8``.
    """

    def __init__(self, width: int, height: int) -> None:
        self.pixels = np.full((height, width, 3), 255, dtype=np.uint8)
        self._texts: list[tuple] = []

    @property
    def height(self) -> int:
        return self.pixels.shape[0]

    @property
    def width(self) -> int:
        return self.pixels.shape[1]

    def text(
        self,
        x: float,
        y: float,
        text: str,
        *,
        size: int = NORMAL,
        anchor: str = "la",
        colour: tuple[int, int, int] = BLACK,
        vertical: bool = False,
    ) -> None:
        """Write ``text`` at pixel ``(x, y)`` (drawn over everything else when the sheet is
        saved); ``anchor`` is Pillow's (``"la"`` left and ascender, ``"mm"`` middle, ``"rm"``
        right-middle, ...). ``vertical`` turns it a quarter turn anticlockwise, centred on
        ``(x, y)``."""
        self._texts.append((x, y, text, size, anchor, colour, vertical))

    def _draw_texts(self, image) -> None:
        from PIL import Image, ImageDraw

        draw = ImageDraw.Draw(image)
        for x, y, text, size, anchor, colour, vertical in self._texts:
            font = _font(size)
            if not vertical:
                draw.text((x, y), text, fill=colour, font=font, anchor=anchor)
                continue
            left, top, right, bottom = font.getbbox(text)
            label = Image.new("RGB", (right - left + 2, bottom - top + 2), WHITE)
            ImageDraw.Draw(label).text((1 - left, 1 - top), text, fill=colour, font=font)
            label = label.transpose(Image.Transpose.ROTATE_90)
            image.paste(label, (round(x - label.width / 2), round(y - label.height / 2)))

    def paste(self, image: np.ndarray, left: int, top: int) -> None:
        """Copy an ``(h, w, 3) uint8`` image with its top-left corner at ``(left, top)``
        (clipped to the sheet)."""
        height, width = image.shape[:2]
        rows = slice(max(top, 0), min(top + height, self.height))
        cols = slice(max(left, 0), min(left + width, self.width))
        self.pixels[rows, cols] = image[
            rows.start - top : rows.stop - top, cols.start - left : cols.stop - left
        ]

    def rectangle(self, left: int, top: int, width: int, height: int, colour) -> None:
        """Fill a rectangle of pixels."""
        self.pixels[max(top, 0) : top + height, max(left, 0) : left + width] = colour

    def outline(self, left: int, top: int, width: int, height: int, colour=BLACK) -> None:
        """A one-pixel rectangle around the given area."""
        right, bottom = left + width, top + height
        self.pixels[top - 1, left - 1 : right + 1] = colour
        self.pixels[bottom, left - 1 : right + 1] = colour
        self.pixels[top - 1 : bottom + 1, left - 1] = colour
        self.pixels[top - 1 : bottom + 1, right] = colour

    def save(self, path: Path) -> Path:
        """Write the sheet as PNG (creating its folder); return the path."""
        from PIL import Image

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        image = Image.fromarray(self.pixels)
        self._draw_texts(image)
        image.save(path, format="PNG", **PNG_OPTIONS)
        return path


@dataclass(frozen=True)
class Frame:
    """A rectangle of a sheet (pixels) showing data ``x_range`` x ``y_range`` (y up).

    A range may run backwards (e.g. image rows, ``(height, 0)``, to put row 0 on top).
    """

    left: int
    top: int
    width: int
    height: int
    x_range: tuple[float, float]
    y_range: tuple[float, float]

    @classmethod
    def fitted(
        cls,
        x_range: tuple[float, float],
        y_range: tuple[float, float],
        left: int,
        top: int,
        width: int,
        height: int,
    ) -> Frame:
        """The frame of at most ``width`` x ``height`` pixels, centred in that area, that
        shows the ranges at equal scale on both axes (the shorter range is widened)."""
        x_span = max(x_range[1] - x_range[0], 1e-12)
        y_span = max(y_range[1] - y_range[0], 1e-12)
        scale = min(width / x_span, height / y_span)
        x_mid, y_mid = 0.5 * sum(x_range), 0.5 * sum(y_range)
        half_x, half_y = 0.5 * width / scale, 0.5 * height / scale
        return cls(
            left,
            top,
            width,
            height,
            (x_mid - half_x, x_mid + half_x),
            (y_mid - half_y, y_mid + half_y),
        )

    def to_pixels(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional pixel ``(columns, rows)`` of data points."""
        (x0, x1), (y0, y1) = self.x_range, self.y_range
        columns = self.left + (np.asarray(x, dtype=float) - x0) * (self.width / (x1 - x0))
        rows = self.top + (y1 - np.asarray(y, dtype=float)) * (self.height / (y1 - y0))
        return columns, rows

    def points(
        self,
        sheet: Sheet,
        x: np.ndarray,
        y: np.ndarray,
        colours: np.ndarray,
        radius_px: float = 1.0,
        depth: np.ndarray | None = None,
    ) -> None:
        """Discs of ``radius_px`` at the points, ``colours`` ``(N, 3) uint8`` (or one
        colour); where discs overlap the point with the largest ``depth`` (nearest the
        viewer) shows, else the later point. Clipped to the frame."""
        count = len(np.asarray(x))
        if count == 0:
            return
        colours = np.broadcast_to(np.asarray(colours, dtype=np.uint8), (count, 3))
        columns, rows = self.to_pixels(x, y)
        reach = int(np.ceil(radius_px))
        d_row, d_col = np.mgrid[-reach : reach + 1, -reach : reach + 1]
        disc = d_row**2 + d_col**2 <= radius_px**2 + 0.5
        rows = (np.floor(rows)[:, None] + d_row[disc]).astype(np.intp).ravel()
        columns = (np.floor(columns)[:, None] + d_col[disc]).astype(np.intp).ravel()
        owner = np.repeat(np.arange(count), np.count_nonzero(disc))
        inside = (
            (rows >= self.top)
            & (rows < self.top + self.height)
            & (columns >= self.left)
            & (columns < self.left + self.width)
        )
        rows, columns, owner = rows[inside], columns[inside], owner[inside]
        flat = rows * sheet.width + columns
        rank = owner if depth is None else np.argsort(np.argsort(depth, kind="stable"))[owner]
        order = np.lexsort((rank, flat))
        last = np.append(flat[order][1:] != flat[order][:-1], True)
        shown = order[last]
        sheet.pixels.reshape(-1, 3)[flat[shown]] = colours[owner[shown]]

    def line(self, sheet: Sheet, start, end, colour, width_px: float = 1.5) -> None:
        """A straight line between two data points, clipped to the frame."""
        c0, r0 = self.to_pixels(*start)
        c1, r1 = self.to_pixels(*end)
        steps = int(np.ceil(2.0 * np.hypot(c1 - c0, r1 - r0))) + 1
        t = np.linspace(0.0, 1.0, min(steps, 100_000))
        xs = start[0] + t * (end[0] - start[0])
        ys = start[1] + t * (end[1] - start[1])
        self.points(sheet, xs, ys, colour, radius_px=0.5 * width_px)

    def triangles(self, sheet: Sheet, xy: np.ndarray, faces: np.ndarray, colour) -> None:
        """Fill the triangles ``faces`` (F, 3) over vertices ``xy`` (V, 2) (a mesh's
        silhouette): every pixel whose centre lies inside some triangle, clipped to the
        frame. Scan-converted row by row: each (triangle, pixel row) pair gives one span."""
        columns, rows = self.to_pixels(xy[:, 0], xy[:, 1])
        # Pixel (c, r) covers [c, c + 1) x [r, r + 1); shifted so its centre is at (c, r).
        corners = np.stack([columns, rows], axis=1)[np.asarray(faces)] - 0.5  # (F, 3, 2)
        first_row = np.maximum(np.ceil(corners[:, :, 1].min(axis=1)), self.top)
        last_row = np.minimum(np.floor(corners[:, :, 1].max(axis=1)), self.top + self.height - 1)
        count = np.maximum(last_row - first_row + 1, 0).astype(np.intp)
        triangle = np.repeat(np.arange(len(count)), count)
        row = first_row[triangle] + (
            np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        )
        low = np.full(len(row), np.inf)
        high = np.full(len(row), -np.inf)
        for k in range(3):
            p, q = corners[triangle, k], corners[triangle, (k + 1) % 3]
            crosses = (np.minimum(p[:, 1], q[:, 1]) <= row) & (row <= np.maximum(p[:, 1], q[:, 1]))
            dy = np.where(p[:, 1] == q[:, 1], 1.0, q[:, 1] - p[:, 1])
            t = np.clip((row - p[:, 1]) / dy, 0.0, 1.0)
            x = p[:, 0] + t * (q[:, 0] - p[:, 0])
            low = np.where(crosses, np.minimum(low, x), low)
            high = np.where(crosses, np.maximum(high, x), high)
            flat = crosses & (p[:, 1] == q[:, 1])  # a horizontal edge on the row: both ends
            low = np.where(flat, np.minimum(low, q[:, 0]), low)
            high = np.where(flat, np.maximum(high, q[:, 0]), high)
        first = np.maximum(np.ceil(low), self.left)
        last = np.minimum(np.floor(high), self.left + self.width - 1)
        span = first <= last
        row, first, last = (a[span].astype(np.intp) for a in (row, first, last))
        # +1 where a span starts, -1 after it ends; a running sum along each row marks it.
        stride = sheet.width + 1
        size = sheet.height * stride
        change = np.bincount(row * stride + first, minlength=size) - np.bincount(
            row * stride + last + 1, minlength=size
        )
        covered = np.cumsum(change.reshape(sheet.height, stride), axis=1)[:, :-1] > 0
        sheet.pixels[covered] = colour

    def axes(self, sheet: Sheet, xlabel: str = "", ylabel: str = "", title: str = "") -> None:
        """Box, ticks with labels at 1-2-5 steps, axis labels and a title (above)."""
        sheet.outline(self.left, self.top, self.width, self.height)
        bottom = self.top + self.height
        for value in nice_ticks(*self.x_range):
            column = round(self.to_pixels(value, 0.0)[0])
            sheet.pixels[bottom : bottom + 5, column] = BLACK
            sheet.text(column, bottom + 6, tick_label(value), size=SMALL, anchor="mt")
        label_right = self.left
        for value in nice_ticks(*self.y_range):
            row = round(self.to_pixels(0.0, value)[1])
            sheet.pixels[row, self.left - 5 : self.left] = BLACK
            sheet.text(self.left - 7, row, tick_label(value), size=SMALL, anchor="rm")
            label_right = min(
                label_right, self.left - 7 - int(_font(SMALL).getlength(tick_label(value)))
            )
        if xlabel:
            sheet.text(self.left + self.width / 2, bottom + 22, xlabel, anchor="mt")
        if ylabel:
            sheet.text(label_right - 12, self.top + self.height / 2, ylabel, vertical=True)
        if title:
            lines = title.split("\n")
            for k, line in enumerate(lines):
                y = self.top - 8 - (len(lines) - 1 - k) * (NORMAL + 4)
                sheet.text(self.left + self.width / 2, y, line, anchor="md")


def colour_bar(
    sheet: Sheet,
    left: int,
    top: int,
    height: int,
    colour_map_name: str,
    low: float,
    high: float,
    label: str,
    *,
    width: int = 16,
    beyond_high: bool = False,
) -> None:
    # Ten parameters: where to draw, the scale and its label, as a plotting call takes them.
    """A vertical colour bar from ``low`` (bottom) to ``high`` (top) with ticks and a
    label; ``beyond_high`` caps it with a triangle in the top colour (values above
    ``high`` are drawn in it)."""
    values = np.linspace(high, low, height)
    strip = colour_map(colour_map_name, values, low, high)
    sheet.pixels[top : top + height, left : left + width] = strip[:, None, :]
    sheet.outline(left, top, width, height)
    if beyond_high:
        cap = Frame(left, top - width, width, width, (0.0, 1.0), (0.0, 1.0))
        cap.triangles(
            sheet, np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]]), np.array([[0, 1, 2]]), strip[0]
        )
    scale = Frame(left, top, width, height, (0.0, 1.0), (low, high))
    widest = 0
    for value in nice_ticks(low, high):
        row = round(scale.to_pixels(0.0, value)[1])
        sheet.pixels[row, left + width : left + width + 4] = BLACK
        sheet.text(left + width + 6, row, tick_label(value), size=SMALL, anchor="lm")
        widest = max(widest, int(_font(SMALL).getlength(tick_label(value))))
    sheet.text(left + width + 18 + widest, top + height / 2, label, vertical=True)
