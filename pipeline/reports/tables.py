"""Plain-text tables and lines for terminal output."""

from __future__ import annotations

import logging
import textwrap
from collections.abc import Collection, Sequence

#: Columns the commands' output keeps within (a terminal's usual width); ``--wide`` tables
#: show every column however wide.
TERMINAL_WIDTH = 100


def format_table(
    header: Sequence[str],
    rows: Sequence[Sequence[object]],
    hide: Collection[str] = (),
) -> str:
    """Left-aligned columns separated by two spaces, with a dashed rule under the header.

    Args:
        hide: the names of the columns to leave out, so one table can be printed narrow
            or ``--wide``.
    """
    keep = [i for i, name in enumerate(header) if name not in hide]
    cells = [[str(header[i]) for i in keep], *[[str(row[i]) for i in keep] for row in rows]]
    widths = [max(len(row[i]) for row in cells) for i in range(len(keep))]
    lines = [
        "  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)).rstrip()
        for row in cells
    ]
    lines.insert(1, "  ".join("-" * width for width in widths))
    return "\n".join(lines)


def wrapped(text: str) -> str:
    """``text`` broken into lines of at most :data:`TERMINAL_WIDTH` columns at spaces, the
    lines after the first indented by two (a word longer than a line, a path say, stays
    whole)."""
    return textwrap.fill(
        text,
        TERMINAL_WIDTH,
        subsequent_indent="  ",
        break_long_words=False,
        break_on_hyphens=False,
    )


class WrappedFormatter(logging.Formatter):
    """A log record's message :func:`wrapped` to the terminal's width, as the tables are:
    the warnings name a file first, and a path alone can fill a line."""

    def format(self, record: logging.LogRecord) -> str:
        return wrapped(super().format(record))
