"""Reading recorded data: captures (clouds, depth images, bags).

What is named here keeps its meaning across releases, as :mod:`pipeline.api` does.
Each name loads its module when it is first imported, so a plugin pays only for the
kernels it uses (``symfuse plugins`` imports every plugin and must stay quick).
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

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


def __getattr__(name: str) -> Any:
    try:
        module, original = _SOURCES[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(import_module(module), original)
    globals()[name] = value
    return value
