"""symfuse: visuo-tactile reconstruction of symmetric objects (the core package).

Plugins import :data:`hookimpl` from here and the stage contracts from
:mod:`pipeline.stages`.

Both names load on first use: the ``symfuse`` command installs its Ctrl-C handling
(:mod:`pipeline.entry`) before anything heavy is imported, and importing it runs this file
first.
"""

from __future__ import annotations

__all__ = ["__version__", "hookimpl"]


# Unannotated return (type checkers take it as Any): importing typing for the annotation
# would cost the console script a few milliseconds before its Ctrl-C handler is in place.
def __getattr__(name: str):
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
