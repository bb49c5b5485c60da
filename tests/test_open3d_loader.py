"""open3d imports on machines without a system libusb (the libusb-package preload)."""

from __future__ import annotations

import ctypes.util
import subprocess
import sys

import pytest

SYSTEM_HAS_LIBUSB = ctypes.util.find_library("usb-1.0") is not None


def run_python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)


def test_open3d_loads_through_the_loader():
    done = run_python(
        "from pipeline.io.open3d_loader import open3d\n"
        "o3d = open3d()\n"
        "import numpy as np\n"
        "cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.eye(3)))\n"
        "print(len(cloud.points))"
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "3"


@pytest.mark.skipif(SYSTEM_HAS_LIBUSB, reason="this machine has a system libusb-1.0")
def test_plain_import_fails_without_the_preload_and_the_loader_uses_the_wheel():
    plain = run_python("import open3d")
    assert plain.returncode != 0
    assert "libusb-1.0.so.0" in plain.stderr
    loaded = run_python(
        "from pipeline.io.open3d_loader import preload_libusb\nprint(preload_libusb())"
    )
    assert loaded.returncode == 0, loaded.stderr
    assert "libusb_package" in loaded.stdout


def test_the_loader_leaves_plotly_and_dash_until_a_plotly_view_is_drawn():
    done = run_python(
        "import sys\n"
        "from pipeline.io.open3d_loader import open3d\n"
        "o3d = open3d()\n"
        "print(sorted(m for m in ('plotly', 'dash', 'IPython') if m in sys.modules))\n"
        "import numpy as np\n"
        "cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.eye(3)))\n"
        "figure = o3d.visualization.get_plotly_fig([cloud])\n"
        "print(type(figure).__module__.split('.')[0], len(figure.data[0].x))\n"
        "import open3d.visualization.draw_plotly as real\n"
        "print(real.get_plotly_fig.__module__)\n"
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[:3] == [
        "[]",
        "plotly 3",
        "open3d.visualization.draw_plotly",
    ]
