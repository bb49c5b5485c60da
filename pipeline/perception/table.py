"""The supporting table plane: fitted by RANSAC (open3d) or taken from a known height.

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

    def z_at(self, xy_m: np.ndarray) -> float:
        """The plane's z at the horizontal position ``xy_m`` ``(2,)``, metres."""
        n = self.normal
        return float((self.offset_m - n[:2] @ np.asarray(xy_m, dtype=np.float64)) / n[2])


def table_from_height(table_height_m: float) -> TablePlane:
    """The horizontal plane ``z = table_height_m``."""
    return TablePlane(normal=np.array([0.0, 0.0, 1.0]), offset_m=float(table_height_m))


#: Least-squares refits of a RANSAC plane to its inliers, at most.
MAX_REFITS = 10


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
    max_planes: int = 3,
) -> tuple[TablePlane, np.ndarray]:
    """Find the dominant near-horizontal plane by RANSAC (open3d's ``segment_plane``), then
    refit it to its inliers.

    RANSAC runs on a random subsample of ``sample_size`` points (the table holds most of a
    scene, so a few thousand points find it as well as all of them, in a fraction of the
    time). A plane whose normal is more than ``max_tilt_rad`` from +z (a wall, a large box
    side) is set aside with its inliers and RANSAC runs again on the rest, up to
    ``max_planes`` times. The winner is refitted by least squares to all its inliers over
    the whole cloud until they settle.

    Args:
        points_robot: ``(N, 3)`` scene points, metres.
        rng: random generator (seeds the subsample and open3d's RANSAC: the fit is
            reproducible).
        inlier_distance_m: distance from the plane that counts as on it.
        iterations: RANSAC iterations (random point triples) per plane.
        max_tilt_rad: largest accepted angle between the plane normal and +z.
        sample_size: points RANSAC sees.
        max_planes: planes tried before giving up.

    Returns:
        The plane and the ``(N,)`` boolean inlier mask.

    Raises:
        ValueError: fewer than 3 points, or no near-horizontal plane was found.
    """
    from pipeline.io.open3d_loader import open3d

    points = np.asarray(points_robot, dtype=np.float64)
    if len(points) < 3:
        raise ValueError(f"RANSAC needs at least 3 points, got {len(points)}")
    o3d = open3d()
    o3d.utility.random.seed(int(rng.integers(2**31)))
    sample = points[rng.choice(len(points), size=min(sample_size, len(points)), replace=False)]
    level = None
    for _ in range(max_planes):
        if len(sample) < 3:
            break
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(sample))
        (a, b, c, d), on_plane = cloud.segment_plane(inlier_distance_m, 3, iterations)
        normal = np.array([a, b, c]) / np.linalg.norm([a, b, c])
        sign = 1.0 if normal[2] >= 0.0 else -1.0
        if sign * normal[2] >= np.cos(max_tilt_rad):
            level = (sign * normal, -sign * d / np.linalg.norm([a, b, c]))
            break
        sample = np.delete(sample, np.asarray(on_plane, dtype=np.int64), axis=0)
    if level is None:
        raise ValueError("RANSAC found no plane within the allowed tilt of horizontal")
    normal, offset, inliers = refit_until_settled(points, *level, inlier_distance_m)
    return TablePlane(normal=normal, offset_m=float(offset)), inliers


def refit_until_settled(
    points: np.ndarray, normal: np.ndarray, offset: float, inlier_distance_m: float
) -> tuple[np.ndarray, float, np.ndarray]:
    """Refit the plane ``normal . p = offset`` to its inliers by least squares until they
    stop changing (at most :data:`MAX_REFITS` times); return it with its inlier mask.

    open3d's RANSAC samples on several threads, so its plane varies slightly from run to
    run even with a seed; the refit settles on the same least-squares plane from any of
    them, which makes the fit reproducible.
    """
    inliers = np.abs(points @ normal - offset) < inlier_distance_m
    for _ in range(MAX_REFITS):
        if inliers.sum() < 3:
            break
        normal, offset = plane_through(points[inliers])
        settled = np.abs(points @ normal - offset) < inlier_distance_m
        if np.array_equal(settled, inliers):
            break
        inliers = settled
    return normal, offset, inliers


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


@dataclass(frozen=True)
class TableFit:
    """The table as the scene's own points show it: the plane refitted to the points on
    it, and how far they scatter about it at each distance from the camera.

    Attributes:
        plane: the refitted plane, robot frame.
        range_m: ``(B,)`` increasing distances from the camera (m), the medians of ``B``
            bins of the table points' distances.
        sigma_m: ``(B,)`` robust standard deviation (m; 1.4826 times the median absolute
            deviation) of the table points' heights above ``plane`` in each bin.
        points: how many table points the fit saw.
    """

    plane: TablePlane
    range_m: np.ndarray
    sigma_m: np.ndarray
    points: int

    def sigma_at(self, range_m: np.ndarray) -> np.ndarray:
        """The table's height scatter (m) at distances ``range_m`` (m) from the camera,
        interpolated between bins (the nearest bin's beyond them)."""
        return np.interp(range_m, self.range_m, self.sigma_m)


#: Fewest table points a :class:`TableFit` is measured on, and fewest per range bin.
MIN_TABLE_POINTS = 200
#: Range bins of a :class:`TableFit`, at most.
TABLE_RANGE_BINS = 8
#: Half-width of the band about the plane that holds the table's points, in robust
#: standard deviations (a normal residual lies outside it once in 16 000).
TABLE_BAND_SIGMAS = 4.0


def measure_table(
    points_robot: np.ndarray,
    viewpoint_robot: np.ndarray,
    table: TablePlane,
    band_m: float,
    *,
    ranges_m: np.ndarray | None = None,
) -> TableFit:
    """Refit ``table`` to the points within ``band_m`` of it and measure their scatter by
    distance from the camera; then set the band about the refitted plane to
    :data:`TABLE_BAND_SIGMAS` times the scatter measured at each point's distance (or
    ``band_m``, when that is wider) and measure again, until the table's points settle
    (at most :data:`MAX_REFITS` times): a noisier sensor than ``band_m`` allows for is not
    under-estimated, and a plane handed in tilted or offset is followed to the table.

    The refit takes the plane the table's points lie on, whatever the plane handed in
    (a known height under a slightly miscalibrated camera, a RANSAC plane): its tilt and
    offset relative to them is gone, and what is left is the sensor's noise and the
    table's unevenness, which the scatter holds.

    Args:
        points_robot: ``(N, 3)`` scene points, metres, robot frame.
        viewpoint_robot: ``(3,)`` camera position, robot frame.
        table: the plane to start from.
        band_m: first half-width of the band of table points about ``table`` (m).
        ranges_m: ``(N,)`` each point's distance from ``viewpoint_robot`` (m), when the
            caller has them (computed here otherwise).

    Raises:
        ValueError: fewer than :data:`MIN_TABLE_POINTS` points lie on the table.
    """
    points = np.asarray(points_robot, dtype=np.float64)
    distance = ranges_m
    if distance is None:
        distance = np.linalg.norm(points - np.asarray(viewpoint_robot, dtype=np.float64), axis=1)
    band = np.full(len(points), float(band_m))
    normal, offset = np.asarray(table.normal, dtype=np.float64), float(table.offset_m)
    previous = None
    for _ in range(MAX_REFITS):
        on_table = np.abs(points @ normal - offset) < band
        if previous is not None and np.array_equal(on_table, previous):
            break
        previous = on_table
        if on_table.sum() < MIN_TABLE_POINTS:
            raise ValueError(
                f"{int(on_table.sum())} points lie within {band_m * 1000:.1f} mm of the table "
                f"(< {MIN_TABLE_POINTS})"
            )
        table_points = points[on_table]
        normal, offset = plane_through(table_points)
        residual = table_points @ normal - offset
        ranges = distance[on_table]
        bins = max(1, min(TABLE_RANGE_BINS, len(ranges) // MIN_TABLE_POINTS))
        edges = np.quantile(ranges, np.linspace(0.0, 1.0, bins + 1))
        which = np.clip(np.searchsorted(edges, ranges, side="right") - 1, 0, bins - 1)
        centres, sigmas = np.empty(bins), np.empty(bins)
        for b in range(bins):
            in_bin = which == b
            r = residual[in_bin]
            centres[b] = np.median(ranges[in_bin])
            sigmas[b] = 1.4826 * np.median(np.abs(r - np.median(r)))
        fit = TableFit(TablePlane(normal, float(offset)), centres, sigmas, int(on_table.sum()))
        band = np.maximum(band_m, TABLE_BAND_SIGMAS * fit.sigma_at(distance))
    return fit
