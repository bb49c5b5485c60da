"""Taxel-layout geometry of tactile pads: pure numpy/scipy, no simulator.

Pad frame convention (shared with ``robots/*.urdf``): the origin is the centre of the pad's
taxel grid on the plane of its flat part, ``z`` is the outward normal of that flat part
(pointing out of the pad, toward the grasped object), ``x`` runs along the rows (the row
index grows with ``x``, toward the fingertip) and ``y`` across them. Taxels are numbered
row-major: ``index = row * cols + col``.

A pad may curve away from the object at its tip (the SDH-2 distal pad): its last
``curved_rows`` rows lie on a cylinder of radius ``radius_m`` whose axis is parallel to
``y``, tangent to the flat part where the curve starts. Taxel spacing is the pitch measured
along the surface, so the grid is the flat grid rolled onto that curve.
"""

from __future__ import annotations

import numpy as np


def pad_grid(
    rows: int,
    cols: int,
    pitch_m: float,
    curved_rows: int = 0,
    radius_m: float = np.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Taxel centres and outward unit normals of one pad, in the pad frame.

    Args:
        rows, cols: grid size (rows along ``x``, columns along ``y``).
        pitch_m: centre-to-centre distance along the surface, metres.
        curved_rows: how many of the rows with the largest ``x`` lie on the curve.
        radius_m: radius of the curved part, metres (ignored when ``curved_rows`` is 0).

    Returns:
        ``(positions, normals)``, each ``(rows * cols, 3)`` float64, row-major.
    """
    if rows < 1 or cols < 1 or pitch_m <= 0.0:
        raise ValueError(f"pad grid needs rows, cols >= 1 and pitch > 0, got {rows}x{cols}")
    if not 0 <= curved_rows <= rows:
        raise ValueError(f"curved_rows must be within 0..{rows}, got {curved_rows}")
    if curved_rows and not (np.isfinite(radius_m) and radius_m > 0.0):
        raise ValueError(f"a curved pad needs a finite positive radius, got {radius_m}")
    x_unrolled = (np.arange(rows) - (rows - 1) / 2.0) * pitch_m
    y = (np.arange(cols) - (cols - 1) / 2.0) * pitch_m
    x_row = x_unrolled.copy()
    z_row = np.zeros(rows)
    nx_row = np.zeros(rows)
    nz_row = np.ones(rows)
    if curved_rows:
        flat_rows = rows - curved_rows
        x_start = x_unrolled[0] - pitch_m / 2.0 + flat_rows * pitch_m
        curved = np.arange(flat_rows, rows)
        angle = (x_unrolled[curved] - x_start) / radius_m
        x_row[curved] = x_start + radius_m * np.sin(angle)
        z_row[curved] = -radius_m * (1.0 - np.cos(angle))
        nx_row[curved] = np.sin(angle)
        nz_row[curved] = np.cos(angle)
    positions = np.empty((rows, cols, 3))
    positions[..., 0] = x_row[:, None]
    positions[..., 1] = y[None, :]
    positions[..., 2] = z_row[:, None]
    normals = np.zeros((rows, cols, 3))
    normals[..., 0] = nx_row[:, None]
    normals[..., 2] = nz_row[:, None]
    return positions.reshape(-1, 3), normals.reshape(-1, 3)


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
