"""The symmetries of a mesh, found by search: its mirror planes and its rotation axes.

A mirror plane or a rotation axis of a solid passes through the centroid of its surface, so
the search only has to find directions. Every direction of a Fibonacci half-sphere is tried
as a plane normal (the surface mirrored across the plane through the centroid) and as an
axis (the surface turned about it by :data:`TEST_ANGLES_RAD`); a hypothesis' residual is the
mean distance of the moved surface samples from the surface. The best local minima are
refined (Nelder-Mead over the direction's two angles and the plane's offset or the axis'
two across coordinates) and kept when their residual is within the tolerance of the
sampling floor: the residual the identity itself has with an independent set of samples.

Planes containing an accepted axis follow from it and are not listed; a sphere lists several
axes. Pure numeric: arrays in, :class:`~pipeline.types.Symmetry` out, in the mesh's frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from pipeline.metrics import sample_surface
from pipeline.types import Symmetry

#: The angles a candidate axis turns the surface by (rad). None is a multiple of 360/k deg
#: for k <= 8, so an object with a k-fold symmetry only (a box, 2- or 4-fold about its
#: height) is not taken for a body of revolution.
TEST_ANGLES_RAD = tuple(np.radians([37.0, 101.0, 157.0]))


#: Changes whenever the search would find other symmetries: cached results of an older
#: version are not reused.
SEARCH_VERSION = 1

#: The cap of the residual the directions are compared with, over the mesh's size.
COARSE_CAP = 0.1


@dataclass(frozen=True)
class SearchSettings:
    """How thoroughly :func:`mesh_symmetries` searches.

    Attributes:
        samples: surface samples moved by every hypothesis.
        reference_samples: surface samples the moved ones are measured against.
        directions: candidate directions on the half-sphere (``sqrt(2 pi / directions)``
            rad apart: 10 deg for 200).
        refined: best local minima of each kind refined.
        tolerance_m: a symmetry is kept when it moves at most ``outlier_share`` of the
            samples farther from the surface than twice the sampling floor plus
            ``max(tolerance_m, relative_tolerance * size)`` (``size``: the bounding box
            diagonal): a mug's handle, turned about the body's axis, is more than that.
        relative_tolerance: see ``tolerance_m``.
        outlier_share: see ``tolerance_m``.
        distinct_deg: two planes (or axes) closer than this are the same one.
    """

    samples: int = 600
    reference_samples: int = 10_000
    directions: int = 200
    refined: int = 4
    tolerance_m: float = 0.002
    relative_tolerance: float = 0.01
    outlier_share: float = 0.03
    distinct_deg: float = 10.0


@dataclass(frozen=True)
class SymmetrySearch:
    """What :func:`mesh_symmetries` found.

    Attributes:
        symmetries: the accepted planes and axes (kinds ``"plane"`` and ``"axis"``), best
            first within each kind, planes first; each with its ``residual_m``.
        floor_m: the sampling floor: an independent sample's mean distance from the
            reference samples (m).
        tolerance_m: the distance (m) a kept symmetry moves at most
            :attr:`SearchSettings.outlier_share` of the samples farther than from the surface.
        centroid_m: ``(3,)`` the surface's centroid every candidate passes through before
            refinement.
    """

    symmetries: tuple[Symmetry, ...]
    floor_m: float
    tolerance_m: float
    centroid_m: np.ndarray

    @property
    def kind(self) -> str:
        """``"axis"`` when some axis was accepted, else ``"plane"`` when some plane was, else
        ``"none"``."""
        kinds = {symmetry.kind for symmetry in self.symmetries}
        return "axis" if "axis" in kinds else "plane" if "plane" in kinds else "none"


def half_sphere(count: int) -> np.ndarray:
    """``(count, 3)`` unit vectors spread evenly (a Fibonacci lattice) over ``z >= 0``."""
    index = np.arange(count) + 0.5
    z = 1.0 - index / count
    radius = np.sqrt(1.0 - z**2)
    azimuth = index * math.pi * (3.0 - math.sqrt(5.0))
    return np.column_stack([radius * np.cos(azimuth), radius * np.sin(azimuth), z])


def direction_of(azimuth: float, elevation: float) -> np.ndarray:
    """The unit vector at ``azimuth`` about +z and ``elevation`` above the xy-plane (rad)."""
    return np.array(
        [
            math.cos(elevation) * math.cos(azimuth),
            math.cos(elevation) * math.sin(azimuth),
            math.sin(elevation),
        ]
    )


def angles_of(direction: np.ndarray) -> tuple[float, float]:
    """``(azimuth, elevation)`` of a unit vector (rad)."""
    return float(np.arctan2(direction[1], direction[0])), float(
        np.arcsin(np.clip(direction[2], -1.0, 1.0))
    )


def moved_distances(symmetry: Symmetry, samples: np.ndarray, tree: cKDTree) -> np.ndarray:
    """Distance of every sample, moved by the symmetry, from the tree's points (m): ``(N,)``
    for a plane, ``(N * len(TEST_ANGLES_RAD),)`` for an axis (every test turn)."""
    angles = (math.pi,) if symmetry.is_plane else TEST_ANGLES_RAD
    moved = np.concatenate([symmetry.apply(samples, angle) for angle in angles])
    return tree.query(moved, workers=1)[0]


def residual(symmetry: Symmetry, samples: np.ndarray, tree: cKDTree, cap_m: float) -> float:
    """Mean of the moved samples' distances from the surface, each capped at ``cap_m`` (m):
    a part the symmetry throws into the air (a mug's handle turned about the body's axis)
    counts as much as its share of the surface, however far it lands."""
    return float(np.mean(np.minimum(moved_distances(symmetry, samples, tree), cap_m)))


def mesh_symmetries(
    vertices: np.ndarray, faces: np.ndarray, settings: SearchSettings | None = None
) -> SymmetrySearch:
    """The mirror planes and rotation axes of the mesh ``(vertices, faces)``, in its frame.

    Deterministic (fixed sampling seeds). A scan need not be closed: the missing bottom of
    a scanned can is symmetric about the can's axis, and its centroid stays on the axis.
    """
    settings = settings or SearchSettings()
    vertices = np.asarray(vertices, dtype=np.float64)
    reference = sample_surface(
        vertices, faces, settings.reference_samples, seed=1, skip_support=False
    )
    samples = sample_surface(vertices, faces, settings.samples, seed=2, skip_support=False)
    tree = cKDTree(reference)
    floor = float(np.mean(tree.query(samples, workers=1)[0]))
    size = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    tolerance = 2.0 * floor + max(settings.tolerance_m, settings.relative_tolerance * size)
    # A wrong direction throws most samples farther than the tolerance, where the capped
    # residual is flat: the directions are compared, and first refined, with a cap wide
    # enough to lead toward the symmetry from a lattice step away.
    wide = COARSE_CAP * size
    centroid = reference.mean(axis=0)

    found: list[Symmetry] = []
    # Axes first: the planes through an accepted axis follow from it and are not searched.
    for kind in ("axis", "plane"):
        directions = half_sphere(settings.directions)
        candidates = [Symmetry(kind, d, centroid) for d in directions]
        scores = np.array(
            [
                np.inf if any(_contains(c, a) for a in found) else residual(c, samples, tree, wide)
                for c in candidates
            ]
        )
        starts = local_minima(directions, scores)[: settings.refined]
        for start in (candidates[index] for index in starts if np.isfinite(scores[index])):
            best = _refined(_refined(start, samples, tree, wide), samples, tree, tolerance)
            share = float(np.mean(moved_distances(best, samples, tree) > tolerance))
            distinct = not any(_same(best, other, settings.distinct_deg) for other in found)
            if share <= settings.outlier_share and distinct:
                found.append(best)
    axes = [s for s in found if s.kind == "axis"]
    planes = [s for s in found if s.kind == "plane" and not any(_contains(s, a) for a in axes)]
    planes.sort(key=lambda s: s.residual_m)
    axes.sort(key=lambda s: s.residual_m)
    return SymmetrySearch(tuple(planes + axes), floor, tolerance, centroid)


def local_minima(directions: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Indices of the directions scoring no worse than every neighbour, best first.

    Neighbours are the directions (or their opposites: a plane's normal and an axis have no
    sign) within 1.5 times the lattice's mean spacing, ``sqrt(2 pi / count)`` rad."""
    spacing = math.sqrt(2.0 * math.pi / len(directions))
    near = np.abs(directions @ directions.T) >= math.cos(1.5 * spacing)
    lowest_near = np.where(near, scores[None, :], np.inf).min(axis=1)
    minima = np.flatnonzero(scores <= lowest_near)
    return minima[np.argsort(scores[minima], kind="stable")]


def _refined(start: Symmetry, samples: np.ndarray, tree: cKDTree, cap_m: float) -> Symmetry:
    """``start`` moved to the nearest minimum of its capped residual (Nelder-Mead over the
    direction's angles and the plane's offset or the axis' two across coordinates)."""
    # Imported here: every trial's evaluation imports this module for the search's version
    # (its results are cached) and never runs the search.
    from scipy.optimize import minimize

    azimuth, elevation = angles_of(start.direction)
    u, v = start.across_axes()

    def build(x: np.ndarray) -> Symmetry:
        direction = direction_of(x[0], x[1])
        if start.kind == "plane":
            return Symmetry("plane", direction, start.point_m + x[2] * direction)
        return Symmetry("axis", direction, start.point_m + x[2] * u + x[3] * v)

    x0 = np.array([azimuth, elevation, 0.0] + ([] if start.kind == "plane" else [0.0]))
    steps = np.array([0.05, 0.05] + [0.5 * cap_m] * (len(x0) - 2))
    simplex = np.vstack([x0, x0 + np.diag(steps)])
    result = minimize(
        lambda x: residual(build(x), samples, tree, cap_m),
        x0,
        method="Nelder-Mead",
        options={"initial_simplex": simplex, "xatol": 1e-3, "fatol": 1e-6, "maxiter": 150},
    )
    best = build(result.x)
    return Symmetry(best.kind, best.direction, best.point_m, None, float(result.fun))


def _same(a: Symmetry, b: Symmetry, distinct_deg: float) -> bool:
    """Whether two symmetries of one kind have directions within ``distinct_deg``."""
    cosine = abs(float(a.direction @ b.direction))
    return a.kind == b.kind and cosine >= math.cos(math.radians(distinct_deg))


def _contains(plane: Symmetry, axis: Symmetry, tolerance_deg: float = 10.0) -> bool:
    """Whether a mirror plane contains (within ``tolerance_deg``) a rotation axis: it is then
    one of the axis' infinitely many planes."""
    return abs(float(plane.direction @ axis.direction)) <= math.sin(math.radians(tolerance_deg))
