"""Where the taxels of a tactile pad are: the pad frame and the taxel grid (pure numpy).

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
