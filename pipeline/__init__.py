"""symfuse: visuo-tactile reconstruction of symmetric objects (the core package).

Plugins import :data:`hookimpl` from here and the stage contracts from
:mod:`pipeline.stages`.

Both names load on first use: the ``symfuse`` command installs its Ctrl-C handling
(:mod:`pipeline.entry`) before anything heavy is imported, and importing it runs this file
first.
"""

from __future__ import annotations

from typing import Any

__all__ = ["__version__", "hookimpl"]


def __getattr__(name: str) -> Any:
    if name == "hookimpl":
        from pipeline.hookspecs import hookimpl

        return hookimpl
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("symfuse")
        except PackageNotFoundError:  # running from a checkout that was never installed
            value = "0+unknown"
        globals()["__version__"] = value
        return value
    raise AttributeError(f"module 'pipeline' has no attribute {name!r}")
