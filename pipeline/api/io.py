"""Reading recorded data: captures (clouds, depth images, bags).

What is named here keeps its meaning across releases, as :mod:`pipeline.api` does.
Each name loads its module when it is first imported, so a plugin pays only for the
kernels it uses (``symfuse plugins`` imports every plugin and must stay quick).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipeline.api._lazy import lazy_attributes

if TYPE_CHECKING:
    from pipeline.io.captures import Capture, read_capture

#: Where each name comes from: (module, name there).
_SOURCES = {
    "Capture": ("pipeline.io.captures", "Capture"),
    "read_capture": ("pipeline.io.captures", "read_capture"),
}

__all__ = [
    "Capture",
    "read_capture",
]


__getattr__ = lazy_attributes(__name__, globals(), _SOURCES)
