"""Reading recorded data: captures (clouds, depth images, bags); a hand's URDF.

What is named here keeps its meaning across releases, as :mod:`pipeline.api` does.
Each name loads its module when it is first imported, so a plugin pays only for the
kernels it uses (``symfuse plugins`` imports every plugin and must stay quick).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipeline.api._lazy import lazy_attributes

if TYPE_CHECKING:
    from pipeline.io.captures import Capture, read_capture
    from pipeline.io.hand_urdf import (
        PadGeometry,
        gripper_spec_from_urdf,
        hand_geometry,
        read_hand_geometry,
    )

#: Where each name comes from: (module, name there).
_SOURCES = {
    "Capture": ("pipeline.io.captures", "Capture"),
    "PadGeometry": ("pipeline.io.hand_urdf", "PadGeometry"),
    "gripper_spec_from_urdf": ("pipeline.io.hand_urdf", "gripper_spec_from_urdf"),
    "hand_geometry": ("pipeline.io.hand_urdf", "hand_geometry"),
    "read_capture": ("pipeline.io.captures", "read_capture"),
    "read_hand_geometry": ("pipeline.io.hand_urdf", "read_hand_geometry"),
}

__all__ = [
    "Capture",
    "PadGeometry",
    "gripper_spec_from_urdf",
    "hand_geometry",
    "read_capture",
    "read_hand_geometry",
]


__getattr__ = lazy_attributes(__name__, globals(), _SOURCES)
