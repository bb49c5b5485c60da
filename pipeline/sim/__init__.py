"""Simulation: the PyBullet world (scene, world, cameras and depth-sensor models, hands),
the MuJoCo world (:mod:`.mujoco`), and what both engines share (the hands' models and the
grasp sequence, the table and object bodies, taxel geometry, convex collision parts).

pybullet prints its build time on stderr when imported, and V-HACD its progress on stdout
from C++; :func:`native_output_silenced` keeps both out of the user's terminal. The package
imports pybullet once, silenced, so every module below gets the already-loaded module.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator


@contextlib.contextmanager
def native_output_silenced(*descriptors: int) -> Iterator[None]:
    """Point the process-level file descriptors (default stdout and stderr) at /dev/null
    for the duration of the block; catches what C/C++ code writes, unlike redirecting
    ``sys.stdout``."""
    descriptors = descriptors or (1, 2)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(fd) for fd in descriptors]
    try:
        with open(os.devnull, "wb") as devnull:
            for fd in descriptors:
                os.dup2(devnull.fileno(), fd)
            yield
    finally:
        for fd, copy in zip(descriptors, saved, strict=True):
            os.dup2(copy, fd)
            os.close(copy)


with native_output_silenced(2):
    import pybullet  # noqa: F401  (loaded here so its build-time banner is silenced)
