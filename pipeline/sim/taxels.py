"""Taxels in the robot frame and ray probes along their normals: pure numpy/scipy, no
simulator. The layout of the taxels on a pad, and the pad frame, are
:mod:`pipeline.geometry.pad_layout`'s.
"""

from __future__ import annotations

import numpy as np


def rotations_from_quaternions(quaternions_xyzw: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(P, 3, 3)`` from quaternions ``(P, 4)`` in (x, y, z, w).

    The quaternions are normalised first (PyBullet's are unit only to about 1e-7).
    """
    from scipy.spatial.transform import Rotation  # deferred: planners load with `plugins`

    return Rotation.from_quat(
        np.asarray(quaternions_xyzw, dtype=np.float64).reshape(-1, 4)
    ).as_matrix()


def taxels_to_robot(
    positions_pad: np.ndarray,
    normals_pad: np.ndarray,
    pad_of_taxel: np.ndarray,
    rotations_robot_pad: np.ndarray,
    translations_robot_pad: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Move stacked taxels of several pads from their pad frames into the robot frame.

    Args:
        positions_pad, normals_pad: ``(N, 3)`` taxels, each in its own pad's frame.
        pad_of_taxel: ``(N,)`` int, which pad (row of the next two arrays) each taxel is on.
        rotations_robot_pad: ``(P, 3, 3)`` pad orientations in frame R.
        translations_robot_pad: ``(P, 3)`` pad origins in frame R, metres.

    Returns:
        ``(positions_robot, normals_robot)``, each ``(N, 3)``.
    """
    rotation = rotations_robot_pad[pad_of_taxel]
    positions_robot = np.einsum("nij,nj->ni", rotation, positions_pad)
    positions_robot += translations_robot_pad[pad_of_taxel]
    normals_robot = np.einsum("nij,nj->ni", rotation, normals_pad)
    return positions_robot, normals_robot


def ray_segments(
    positions: np.ndarray, normals: np.ndarray, behind_m: float, beyond_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Start and end points of one probing ray per taxel, along its normal.

    Each ray starts ``behind_m`` inside the pad (behind its surface) and ends ``beyond_m``
    past the surface, so a surface touching or slightly pressed into the pad is still hit.
    """
    return positions - behind_m * normals, positions + beyond_m * normals


def segments_near_box(
    starts: np.ndarray, ends: np.ndarray, box_min: np.ndarray, box_max: np.ndarray
) -> np.ndarray:
    """``(N,)`` bool: which segments' bounding boxes overlap the axis-aligned box.

    A conservative pre-filter: a segment that is False cannot touch anything inside the box.
    """
    low = np.minimum(starts, ends)
    high = np.maximum(starts, ends)
    return np.all((low <= box_max) & (high >= box_min), axis=1)


def surface_gaps(hit_fractions: np.ndarray, behind_m: float, beyond_m: float) -> np.ndarray:
    """Signed distance from each taxel's surface to the first hit along its ray, metres.

    Positive: the hit lies beyond the pad surface (a gap); negative: the object reaches
    behind it (penetration). ``hit_fractions`` are fractions of the segments from
    :func:`ray_segments`; a fraction of 1 or more (no hit) gives ``+inf``.
    """
    fractions = np.asarray(hit_fractions, dtype=np.float64)
    gaps = fractions * (behind_m + beyond_m) - behind_m
    return np.where(fractions < 1.0, gaps, np.inf)
