"""Import open3d on machines without a system libusb.

open3d 0.20's Linux wheel links against ``libusb-1.0.so.0`` (for its RealSense support) and
fails at import where the system lacks it, e.g. a fresh Debian image without root to
``apt install libusb-1.0-0``. The ``libusb-package`` wheel ships that library; loading it
with ``RTLD_GLOBAL`` before open3d makes the dynamic linker resolve open3d's dependency to
it. Every symfuse module gets open3d through :func:`open3d`.

open3d's ``__init__`` also imports ``open3d.visualization``, whose ``draw_plotly`` module
imports plotly and dash (with IPython and requests behind it): more than half of open3d's
import time, for browser plots symfuse never draws. open3d has no switch to skip it, so
:func:`open3d` imports the package with a stand-in for that one module
(:func:`_plotly_deferred`); its functions load the real module on first call.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import importlib
import importlib.util
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

#: The libusb open3d's library links against, and the file ``libusb-package`` ships.
LIBUSB_SONAME = "libusb-1.0.so.0"
LIBUSB_PACKAGED = "libusb-1.0.so"
#: The open3d module that imports plotly and dash when loaded.
PLOTLY_MODULE = "open3d.visualization.draw_plotly"


def preload_libusb() -> str | None:
    """Load a libusb-1.0 globally if the system has none; return the path loaded, if any.

    The system's is looked for by the name open3d links against (the dynamic linker's
    own search: ``ctypes.util.find_library`` would run ``ldconfig`` and a compiler), the
    wheel's in its package folder (importing ``libusb_package`` would import
    ``importlib_resources`` to find the same file).
    """
    if not sys.platform.startswith("linux"):
        return None
    try:
        ctypes.CDLL(LIBUSB_SONAME)
        return None
    except OSError:
        pass
    path = _packaged_libusb()
    ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
    return path


def _packaged_libusb() -> str:
    """The path of the libusb-1.0 the ``libusb-package`` wheel ships."""
    spec = importlib.util.find_spec("libusb_package")
    for folder in (spec.submodule_search_locations or []) if spec is not None else []:
        if (path := Path(folder) / LIBUSB_PACKAGED).is_file():
            return str(path)
    import libusb_package  # installed in a form without a plain folder (a zip)

    return str(libusb_package.get_library_path())


def _real_plotly_module() -> ModuleType:
    """The real ``draw_plotly`` module, replacing the stand-in in ``sys.modules``."""
    module = sys.modules.get(PLOTLY_MODULE)
    if module is None or getattr(module, "_symfuse_stand_in", False):
        sys.modules.pop(PLOTLY_MODULE, None)
        module = importlib.import_module(PLOTLY_MODULE)
    return module


def _forwarder(name: str) -> Callable:
    def forward(*args, **kwargs):
        return getattr(_real_plotly_module(), name)(*args, **kwargs)

    forward.__name__ = forward.__qualname__ = name
    forward.__doc__ = f"``{PLOTLY_MODULE}.{name}``, imported (with plotly and dash) on call."
    return forward


@contextlib.contextmanager
def _plotly_deferred() -> Iterator[None]:
    """While open3d imports, ``open3d.visualization.draw_plotly`` is a module whose every
    public name (``from .draw_plotly import draw_plotly`` and the like) is a function that
    imports the real module when called. Afterwards the stand-in leaves ``sys.modules``, so
    ``import open3d.visualization.draw_plotly`` gets the real module.

    Where the wheel has no such module the import goes on untouched.
    """
    spec = importlib.util.find_spec("open3d")
    folder = Path(spec.origin).parent if spec is not None and spec.origin else None
    if folder is None or not (folder / "visualization" / "draw_plotly.py").is_file():
        yield
        return
    stand_in = ModuleType(PLOTLY_MODULE, "plotly views, imported on first call")
    stand_in._symfuse_stand_in = True

    def attribute(name: str) -> Callable:
        if name.startswith("__"):
            raise AttributeError(name)
        return _forwarder(name)

    stand_in.__getattr__ = attribute
    sys.modules[PLOTLY_MODULE] = stand_in
    try:
        yield
    finally:
        if sys.modules.get(PLOTLY_MODULE) is stand_in:
            del sys.modules[PLOTLY_MODULE]


@functools.cache
def open3d() -> ModuleType:
    """The ``open3d`` module, imported after making sure its libusb dependency resolves,
    without its plotly views (see the module docstring)."""
    preload_libusb()
    if "open3d" in sys.modules:
        return sys.modules["open3d"]
    with _plotly_deferred():
        return importlib.import_module("open3d")
