"""The supporting table plane: fitted by RANSAC or taken from a known height.

The plane is ``{p : normal . p = offset_m}`` in the robot frame, with the unit normal
pointing up (``normal_z > 0``), so ``normal . p - offset_m`` is the height above the table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TablePlane:
    """A table plane in the robot frame (unit ``normal`` with positive z, ``offset_m``)."""

    normal: np.ndarray
    offset_m: float

    def height_m(self, points_robot: np.ndarray) -> np.ndarray:
        """Signed height ``(N,)`` of robot-frame points above the plane, metres."""
        return points_robot @ self.normal - self.offset_m


def table_from_height(table_height_m: float) -> TablePlane:
    """The horizontal plane ``z = table_height_m``."""
    return TablePlane(normal=np.array([0.0, 0.0, 1.0]), offset_m=float(table_height_m))


def plane_through(points: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Least-squares plane through ``(N, 3)`` points (N >= 3), normal pointing up."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    normal = vt[-1]
    if normal[2] < 0.0:
        normal = -normal
    return normal, float(normal @ centroid)


def fit_table_ransac(
    points_robot: np.ndarray,
    rng: np.random.Generator,
    *,
    inlier_distance_m: float = 0.005,
    iterations: int = 200,
    max_tilt_rad: float = np.deg2rad(20.0),
    sample_size: int = 5000,
) -> tuple[TablePlane, np.ndarray]:
    """Find the dominant near-horizontal plane by RANSAC, then refit it to its inliers.

    Candidate planes through random point triples whose normal is more than ``max_tilt_rad``
    from +z are discarded (the table is horizontal up to calibration error). Candidates are
    scored on a random subsample of ``sample_size`` points; the winner is refitted by least
    squares to all its inliers over the whole cloud, twice.

    Args:
        points_robot: ``(N, 3)`` scene points, metres.
        rng: random generator (makes the fit reproducible).
        inlier_distance_m: distance from the plane that counts as on it.
        iterations: number of random triples tried.
        max_tilt_rad: largest accepted angle between the plane normal and +z.
        sample_size: points used to score candidates.

    Returns:
        The plane and the ``(N,)`` boolean inlier mask.

    Raises:
        ValueError: fewer than 3 points, or no near-horizontal plane was found.
    """
    points = np.asarray(points_robot, dtype=np.float64)
    if len(points) < 3:
        raise ValueError(f"RANSAC needs at least 3 points, got {len(points)}")
    sample = points[rng.choice(len(points), size=min(sample_size, len(points)), replace=False)]
    triples = points[rng.integers(0, len(points), size=(iterations, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    usable = lengths > 1e-12
    normals = normals[usable] / lengths[usable, None]
    normals *= np.sign(normals[:, 2:3] + (normals[:, 2:3] == 0.0))
    offsets = np.einsum("kj,kj->k", normals, triples[usable, 0])
    level = normals[:, 2] >= np.cos(max_tilt_rad)
    if not np.any(level):
        raise ValueError("RANSAC found no plane within the allowed tilt of horizontal")
    normals, offsets = normals[level], offsets[level]
    counts = (np.abs(sample @ normals.T - offsets) < inlier_distance_m).sum(axis=0)
    best = int(np.argmax(counts))
    normal, offset = normals[best], float(offsets[best])
    for _ in range(2):
        inliers = np.abs(points @ normal - offset) < inlier_distance_m
        if inliers.sum() < 3:
            break
        normal, offset = plane_through(points[inliers])
    inliers = np.abs(points @ normal - offset) < inlier_distance_m
    return TablePlane(normal=normal, offset_m=offset), inliers


def resolve_table(
    points_robot: np.ndarray,
    table_height_m: float | None,
    source: str,
    rng: np.random.Generator,
    *,
    inlier_distance_m: float = 0.005,
    iterations: int = 200,
) -> TablePlane:
    """The table for a scene: ``"known"`` uses ``table_height_m``, ``"ransac"`` fits the
    points, ``"auto"`` uses the known height when there is one and RANSAC otherwise.

    Raises:
        ValueError: ``"known"`` without a height, or RANSAC found no table.
    """
    if source == "known" or (source == "auto" and table_height_m is not None):
        if table_height_m is None:
            raise ValueError("the observation does not know the table height")
        return table_from_height(table_height_m)
    plane, _ = fit_table_ransac(
        points_robot, rng, inlier_distance_m=inlier_distance_m, iterations=iterations
    )
    return plane
