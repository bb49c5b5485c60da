"""Geometric deviation of a completed model from the true mesh (docs/method.md §6): exact
point-to-triangle distances (libigl's AABB tree, in float64) and inside tests
(:mod:`pipeline.metrics.mesh_queries`), summarised per trial.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from pipeline.metrics.mesh_queries import grid_crossings, ray_crossings


@dataclass(frozen=True)
class DeviationSummary:
    """Box-and-whisker summary of point-to-mesh deviations, metres."""

    count: int
    min: float
    q1: float
    median: float
    q3: float
    max: float
    mean: float

    @classmethod
    def from_distances(cls, distances_m: np.ndarray) -> DeviationSummary:
        values = np.asarray(distances_m, dtype=np.float64).reshape(-1)
        if values.size == 0:
            raise ValueError("a deviation summary needs at least one distance")
        q1, median, q3 = np.percentile(values, [25.0, 50.0, 75.0])
        return cls(
            count=int(values.size),
            min=float(values.min()),
            q1=float(q1),
            median=float(median),
            q3=float(q3),
            max=float(values.max()),
            mean=float(values.mean()),
        )

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


class MeshSurface:
    """A triangle mesh ready for repeated distance and inside queries: its bounding-volume
    tree built once, however many point sets are then asked about (a true mesh scored
    against every stage, a model's mesh asked for distances and for its inside).

    Args:
        vertices: ``(V, 3)`` mesh vertices (m).
        faces: ``(F, 3)`` vertex indices of the triangles.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        import igl

        self._vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self._faces = np.ascontiguousarray(faces, dtype=np.int64)
        if self._faces.ndim != 2 or len(self._faces) == 0:
            raise ValueError("the mesh has no triangles")
        self._tree = igl.AABB()
        self._tree.init(self._vertices, self._faces)

    @property
    def triangles(self) -> np.ndarray:
        """``(F, 3, 3)`` the corners of every triangle (m)."""
        return self._vertices[self._faces]

    def distances(self, points: np.ndarray) -> np.ndarray:
        """Unsigned distance (m) of every ``(N, 3)`` point to the surface, same frame as
        the mesh: :func:`point_to_mesh_distances`."""
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), got {points.shape}")
        if len(points) == 0:
            return np.zeros(0)
        squared, _, _ = self._tree.squared_distance(
            self._vertices, self._faces, np.ascontiguousarray(points)
        )
        return np.sqrt(np.asarray(squared, dtype=np.float64).reshape(-1))

    def occupancy(self, points: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: which points lie inside the closed mesh, :func:`mesh_occupancy`."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        votes = np.zeros(len(points), dtype=np.int64)
        triangles = self.triangles
        for axis in range(3):
            ray, _ = ray_crossings(triangles, points, axis)
            votes += np.bincount(ray, minlength=len(points)) % 2
        return votes >= 2

    def column_crossings(
        self, low_xy: np.ndarray, pitch: float, counts: tuple[int, int]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where the vertical lines through the grid ``low_xy + pitch * (i, j)`` (``0 <= i
        < counts[0]``, ``0 <= j < counts[1]``) cross the surface: every crossing's column
        index ``i * counts[1] + j`` and height (m), ordered by column and, within a column,
        upward (:func:`~pipeline.metrics.mesh_queries.grid_crossings`)."""
        column, height = grid_crossings(self.triangles, 2, low_xy, pitch, counts)
        order = np.lexsort((height, column))
        return column[order], height[order]


def point_to_mesh_distances(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray
) -> np.ndarray:
    """Unsigned distance (m) of every point to the surface of a triangle mesh.

    Exact point-to-triangle distances in float64 from libigl's AABB tree (open3d's
    ``RaycastingScene``, which this replaced, answers as fast but in float32 and loads
    open3d, the largest import of a trial). Several point sets against one mesh:
    :class:`MeshSurface`.

    Args:
        points: ``(N, 3)`` points, same frame as the mesh.
        vertices: ``(V, 3)`` mesh vertices (e.g. ``trimesh.Trimesh.vertices``).
        faces: ``(F, 3)`` vertex indices of the triangles.
    """
    return MeshSurface(vertices, faces).distances(points)


def mesh_occupancy(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: which points lie inside a closed triangle mesh.

    Each point's rays along +x, +y and +z count their crossings of the surface (an odd
    count: inside), and the majority of the three decides, so a ray that grazes the
    surface where it is not closed does not flip the answer alone.
    """
    return MeshSurface(vertices, faces).occupancy(points)


def mesh_deviation(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, DeviationSummary]:
    """Per-point distances to the mesh surface (m) and their summary."""
    distances = point_to_mesh_distances(points, vertices, faces)
    return distances, DeviationSummary.from_distances(distances)
