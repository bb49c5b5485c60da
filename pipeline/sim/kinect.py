"""The Kinect v1 depth camera's published numbers: its intrinsics and axial noise.

The simulated Kinect sensor, the synthetic scenes and the tests all take these from here.
"""

from __future__ import annotations

import numpy as np

from pipeline.types import CameraIntrinsics

#: Kinect v1 depth intrinsics, 640x480 (the ROS driver's defaults; principal point from the
#: top-left pixel's centre).
KINECT_V1_INTRINSICS = CameraIntrinsics(
    width=640, height=480, fx=575.8, fy=575.8, cx=314.5, cy=235.5
)


def axial_sigma_m(depth_m: np.ndarray) -> np.ndarray:
    """Standard deviation (m) of the Kinect v1's depth along the optical axis on a surface
    seen face-on: ``0.0012 + 0.0019 (z - 0.4)^2`` with ``z`` the depth (m) (Nguyen, Izadi &
    Lovell 2012, "Modeling Kinect sensor noise for improved 3D reconstruction and
    tracking"; about 1.5 mm at 0.8 m, 2.4 mm at 1.2 m)."""
    return 0.0012 + 0.0019 * (np.asarray(depth_m, dtype=np.float64) - 0.4) ** 2
