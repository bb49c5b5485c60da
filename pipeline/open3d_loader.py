"""Import open3d on machines without a system libusb.

open3d 0.20's Linux wheel links against ``libusb-1.0.so.0`` (for its RealSense support) and
fails at import where the system lacks it, e.g. a fresh Debian image without root to
``apt install libusb-1.0-0``. The ``libusb-package`` wheel ships that library; loading it
with ``RTLD_GLOBAL`` before open3d makes the dynamic linker resolve open3d's dependency to
it. Every symfuse module gets open3d through :func:`open3d`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import importlib
import sys
from types import ModuleType


def preload_libusb() -> str | None:
    """Load a libusb-1.0 globally if the system has none; return the path loaded, if any."""
    if ctypes.util.find_library("usb-1.0"):
        return None
    if not sys.platform.startswith("linux"):
        return None
    import libusb_package

    path = str(libusb_package.get_library_path())
    ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
    return path


@functools.cache
def open3d() -> ModuleType:
    """The ``open3d`` module, imported after making sure its libusb dependency resolves."""
    preload_libusb()
    return importlib.import_module("open3d")
