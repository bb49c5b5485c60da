"""Where Stage 1 starts: a coarse search over the bias translation and the plane
(docs/method.md §3, "Start").

The IEKF is a local method: its correspondences are found around the taxels mapped through
the current state, so a bias of several prior standard deviations puts every pad's gate on
the wrong part of the model, and the filter explains the misfit by whatever moves the model
cheapest under the prior (with three pads, the bias yaw runs off to its divergence bound
while the translation stays near zero). Started at the true translation, with the prior
unchanged, the same cases converge (docs/results.md, "The code's own choices"). So before
the first grasp's Stage 1 the estimator scores a grid of states and starts the iteration
(not the prior, which stays Stage 0's) at the best:

* the horizontal translation on a square grid of :attr:`SearchSettings.step_m` inside the
  prior's ellipse of :attr:`SearchSettings.translation_sigmas` standard deviations;
* the plane's angle (its normal's azimuth; a leaning normal keeps its elevation) at
  ``0, +-1, +-2`` prior stds and its distance from the pivot at ``0, +-1/2, +-1`` of its
  prior std (the IEKF corrects the plane well from a zero bias,
  Figs. 8 and 9; the grid only has to put the back within its reach);
* the yaw and the vertical translation at Stage 0's (both have narrow priors).

Stage 0 stays the start unless the best state scores clearly lower
(:attr:`SearchSettings.keep_margin`): where Stage 0 explains the taxels about as well as
anything on the grid, the paper's iteration runs unchanged (and an easy start is not moved
to a grid point that needs more iterations).

A state's score is the prior's Mahalanobis distance plus, over a few taxels of every pad,
their squared distance to the completed model (the nearer of the front cloud and its mirror
image, read from a distance field of the cloud) in units of
:attr:`SearchSettings.distance_std_m`, truncated at :attr:`SearchSettings.truncation_sigmas`,
so a pad off the model costs a fixed amount however far off it is (a pad on a part the
camera never saw is not forced onto the cloud). Every pad counts as
:attr:`SearchSettings.taxels_per_pad` taxels however many touch: counted as the filter
counts them (a hundred independent taxels on a pad), the data outweighed the prior in
directions it does not measure: on an object whose jaws press on two flat faces the start
moved far along the faces, where the object had hardly moved, and the filter stayed there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.special import gammaincinv

from pipeline.estimation.geometry import normal_derivatives, state_normal
from pipeline.estimation.indexsets import union
from pipeline.geometry.poses import rotation_z

if TYPE_CHECKING:
    from pipeline.estimation.iekf import FusionProblem


#: Plane angle offsets in prior stds and plane distance offsets in prior stds.
ANGLE_SIGMAS = (0.0, -1.0, 1.0, -2.0, 2.0)
OFFSET_SIGMAS = (0.0, -0.5, 0.5, -1.0, 1.0)
#: The components of ``g`` the grid varies: ``b_x, b_y, m_r, m_theta``. (A held component,
#: zero prior variance, gets no offsets: its grid steps are multiples of a zero std.)
_SEARCHED = [1, 2, 4, 5]


@dataclass(frozen=True)
class SearchSettings:
    """The grid and the score of the start search.

    Attributes:
        translation_sigmas: the translation grid covers the prior's ellipse of this many
            standard deviations around Stage 0.
        step_m: spacing of the translation grid (m).
        taxels_per_pad: taxels of each pad scored (evenly spread over its contact).
        voxel_m: voxel edge of the distance field the taxels' distances are read from (m).
        distance_std_m: std of a taxel's distance to a correct model (m): taxel, point
            noise and the field's voxels.
        truncation_sigmas: a taxel further than this many ``distance_std_m`` from the model
            costs the same as one at that distance.
        keep_margin: Stage 0 stays the start unless the best state scores lower by more
            than this (default: the 99 % chi-square quantile of the four searched
            components).
    """

    translation_sigmas: float = 6.0
    step_m: float = 0.005
    taxels_per_pad: int = 6
    voxel_m: float = 0.002
    distance_std_m: float = 0.0025
    truncation_sigmas: float = 3.0
    # The 99 % quantile of chi-square with len(_SEARCHED) degrees of freedom, through the
    # incomplete gamma function: scipy.stats is too heavy to import in every trial.
    keep_margin: float = float(2.0 * gammaincinv(len(_SEARCHED) / 2.0, 0.99))


#: Most voxels along an axis of the distance field (a large object gets coarser voxels).
MAX_FIELD_CELLS = 128


@dataclass(frozen=True)
class DistanceField:
    """Distance (m) to the nearest of some points, truncated, on a voxel grid.

    Each point marks its voxel; the Euclidean distance transform, truncated
    (:func:`truncated_squared_distances`), gives every voxel centre
    its distance to the nearest marked centre, read between centres by trilinear
    interpolation, so a lookup costs a few operations instead of a tree search (within
    about one voxel of the true distance). Beyond the grid, and beyond ``limit_m``
    everywhere, it reads ``limit_m``.
    """

    field: np.ndarray
    lower_m: np.ndarray
    voxel_m: float
    limit_m: float

    @classmethod
    def build(cls, points_m: np.ndarray, voxel_m: float, limit_m: float) -> DistanceField:
        """The field of ``points_m`` (``(N, 3)``) with voxels of ``voxel_m``, no finer than
        :data:`MAX_FIELD_CELLS` per axis, covering them with a margin of ``limit_m``."""
        lower = points_m.min(axis=0) - limit_m - voxel_m
        upper = points_m.max(axis=0) + limit_m + voxel_m
        voxel_m = max(voxel_m, float(np.max(upper - lower)) / MAX_FIELD_CELLS)
        shape = tuple(int(e) + 1 for e in np.ceil((upper - lower) / voxel_m))
        cells = np.rint((points_m - lower) / voxel_m).astype(np.int64)
        squared = truncated_squared_distances(cells, shape, int(np.ceil(limit_m / voxel_m)))
        field = np.minimum(np.sqrt(squared) * voxel_m, limit_m)
        return cls(field, lower, voxel_m, limit_m)

    def __call__(self, queries_m: np.ndarray) -> np.ndarray:
        """The truncated distance at each of ``(..., 3)`` queries, shape ``(...)``."""
        coordinates = ((queries_m.reshape(-1, 3) - self.lower_m) / self.voxel_m).T
        nx, ny, nz = self.field.shape
        x, y, z = coordinates
        inside = (x >= 0) & (y >= 0) & (z >= 0) & (x <= nx - 1) & (y <= ny - 1) & (z <= nz - 1)
        i = np.clip(x.astype(np.int64), 0, nx - 2)
        j = np.clip(y.astype(np.int64), 0, ny - 2)
        k = np.clip(z.astype(np.int64), 0, nz - 2)
        fx, fy, fz = x - i, y - j, z - k
        base = (i * ny + j) * nz + k
        flat = self.field.ravel()
        values = np.zeros(len(base))
        for dx, wx in ((0, 1.0 - fx), (ny * nz, fx)):
            for dy, wy in ((0, 1.0 - fy), (nz, fy)):
                wxy = wx * wy
                corner = base + (dx + dy)
                values += wxy * ((1.0 - fz) * flat[corner] + fz * flat[corner + 1])
        values[~inside] = self.limit_m
        return values.reshape(queries_m.shape[:-1])


def truncated_squared_distances(
    cells: np.ndarray, shape: tuple[int, ...], radius: int
) -> np.ndarray:
    """Squared distance (in voxels) from every voxel of a grid of ``shape`` to the nearest of
    the marked voxels ``cells`` (``(N, 3)`` indices), where that is at most ``radius``
    voxels; inf beyond.

    Within ``radius`` this is the exact Euclidean distance transform, every voxel reached
    from the marked ones by the integer offsets of the ball of ``radius`` (written farthest
    first, so the nearest stays). A distance field truncated within that radius needs no
    more, and the ball costs a third of the whole transform on the start search's grids.
    """
    axis = np.arange(-radius, radius + 1)
    offsets = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    squared = np.einsum("ij,ij->i", offsets, offsets)
    inside = squared <= radius**2
    offsets, squared = offsets[inside], squared[inside]
    farthest_first = np.argsort(-squared, kind="stable")
    # A margin of ``radius`` voxels round the grid: no offset leaves the padded grid.
    padded = np.asarray(shape) + 2 * radius
    strides = np.array([padded[1] * padded[2], padded[2], 1])
    steps = offsets[farthest_first] @ strides
    # The marked cells' keys column by column (numpy multiplies integer matrices without
    # BLAS) and their sorted distinct values over the key range, not by a sort.
    marked = union(sum((cells[:, k] + radius) * int(strides[k]) for k in range(3)))
    nearest = np.full(int(np.prod(padded)), np.inf)
    for step, value in zip(steps, squared[farthest_first].astype(np.float64), strict=True):
        nearest[marked + step] = value
    inner = slice(radius, -radius) if radius else slice(None)
    return nearest.reshape(tuple(padded))[inner, inner, inner]


def scored_taxels(positions_m: np.ndarray, pads: np.ndarray, per_pad: int) -> np.ndarray:
    """Indices of at most ``per_pad`` taxels of every pad, evenly spread in index order."""
    chosen = []
    for pad in np.unique(pads):
        members = np.flatnonzero(pads == pad)
        take = np.unique(np.linspace(0, len(members) - 1, min(per_pad, len(members))).round())
        chosen.append(members[take.astype(np.int64)])
    return np.concatenate(chosen) if chosen else np.empty(0, dtype=np.int64)


def translation_grid(covariance_xy: np.ndarray, sigmas: float, step_m: float) -> np.ndarray:
    """``(K, 2)`` offsets on a square grid of ``step_m`` whose Mahalanobis distance under
    ``covariance_xy`` is at most ``sigmas``; the zero offset first."""
    half = sigmas * np.sqrt(np.diag(covariance_xy))
    axes = [np.arange(-np.floor(h / step_m), np.floor(h / step_m) + 1) * step_m for h in half]
    offsets = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    d2 = np.einsum("ki,ij,kj->k", offsets, np.linalg.inv(covariance_xy), offsets)
    offsets = offsets[d2 <= sigmas**2]
    order = np.argsort(np.linalg.norm(offsets, axis=1), kind="stable")
    return offsets[order]


def search_start(problem: FusionProblem, settings: SearchSettings) -> np.ndarray:
    """The best-scoring state of the grid (see the module docstring), shaped as
    ``problem.g_init``; Stage 0's
    own state when no grasp has taxels or no state scores better."""
    g0 = np.asarray(problem.g_init, dtype=float)
    if not problem.grasps or len(problem.grasps[0].positions_m) == 0:
        return g0
    contacts = problem.grasps[0]
    pads = np.asarray(contacts.pads)
    chosen = scored_taxels(contacts.positions_m, pads, settings.taxels_per_pad)
    taxels = contacts.positions_m[chosen]
    # Every pad counts as taxels_per_pad taxels, however many touch.
    _, pad_of, pad_scored = np.unique(pads[chosen], return_inverse=True, return_counts=True)
    taxel_weight = settings.taxels_per_pad / pad_scored[pad_of]
    limit = settings.truncation_sigmas * settings.distance_std_m
    truncated = DistanceField.build(problem.points_m, settings.voxel_m, limit)
    pivot = problem.pivot_m

    covariance = np.asarray(problem.covariance_init, dtype=float)
    translations = translation_grid(
        covariance[1:3, 1:3], settings.translation_sigmas, settings.step_m
    )
    # Taxel pre-images under every translation (yaw and b_z at Stage 0's): (K, S, 3).
    rotation = rotation_z(g0[0])
    shift = np.zeros((len(translations), 3))
    shift[:, :2] = translations
    shift += g0[1:4]
    pre = np.einsum("ksj,ji->ksi", taxels[None] - pivot - shift[:, None], rotation) + pivot

    front = truncated(pre)
    std_theta = np.sqrt(covariance[5, 5])
    offset_std = _offset_std(covariance, g0, pivot)
    offset0 = g0[4] - state_normal(g0) @ pivot
    planes = [
        (g0[5] + a * std_theta, offset0 + o * offset_std)
        for a in ANGLE_SIGMAS
        for o in OFFSET_SIGMAS
    ]
    information = np.linalg.pinv(covariance[np.ix_(_SEARCHED, _SEARCHED)])
    best_score, best, stage_zero_score = np.inf, g0, None
    candidate = g0.copy()
    for theta, offset in planes:
        candidate[5] = theta
        n = state_normal(candidate)
        m_r = offset + n @ pivot
        back = truncated(pre - 2.0 * ((pre @ n) - m_r)[..., None] * n)
        nearest = np.minimum(front, back) / settings.distance_std_m
        data = (nearest**2 * taxel_weight).sum(axis=1)
        delta = np.column_stack(
            [
                translations,
                np.full(len(translations), m_r - g0[4]),
                np.full(len(translations), theta - g0[5]),
            ]
        )
        prior = np.einsum("ki,ij,kj->k", delta, information, delta)
        score = data + prior
        if stage_zero_score is None:  # the first plane and translation are Stage 0's
            stage_zero_score = float(score[0])
        k = int(np.argmin(score))
        if score[k] < best_score:
            best_score = float(score[k])
            best = g0.copy()
            best[1:3] += translations[k]
            best[4], best[5] = m_r, theta
    if stage_zero_score <= best_score + settings.keep_margin:
        return g0
    return best


def _offset_std(covariance: np.ndarray, g: np.ndarray, pivot_m: np.ndarray) -> float:
    """Prior std of the plane's distance from the pivot, ``m_r - n . c``, at ``g``."""
    jacobian = np.zeros(len(g))
    jacobian[4] = 1.0
    jacobian[5:] = -(normal_derivatives(g) @ pivot_m)
    return float(np.sqrt(jacobian @ covariance @ jacobian))
