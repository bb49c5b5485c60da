"""symfuse: visuo-tactile reconstruction of symmetric objects (the core package).

Plugins import :data:`hookimpl` from here and the stage contracts from
:mod:`pipeline.stages`.
"""

from importlib.metadata import PackageNotFoundError, version

from .hookspecs import hookimpl

try:
    __version__ = version("symfuse")
except PackageNotFoundError:  # running from a checkout that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__", "hookimpl"]
