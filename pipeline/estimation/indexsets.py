"""Sets of point indices and voxel keys without sorting or hashing.

The filter keeps sets of point indices (the active set, the moved points, the points a gain
couples) and bins points into voxels by integer key many times per iteration. Every such
value is a small non-negative integer (below the number of points, or below the number of
cells of a grid), so a boolean mask or a count over the whole range replaces the hash table
and sort behind ``np.unique``, ``np.union1d`` and their inverse: ``O(n + range)`` with a tiny
constant, against ``O(n log n)`` (at 100,000 points ``np.unique`` cost more than all the
Gaussian sums of an iteration). The results are exactly those of numpy's set routines.
"""

from __future__ import annotations

import numpy as np

#: Largest key range, as a multiple of the number of keys, for which
#: :func:`unique_inverse` counts over the range instead of sorting.
DENSE_RANGE_FACTOR = 8


def union(*indices: np.ndarray) -> np.ndarray:
    """Sorted distinct values of non-negative integer arrays (as ``np.unique`` of their
    concatenation, int64)."""
    nonempty = [np.asarray(values) for values in indices if len(values)]
    if not nonempty:
        return np.empty(0, dtype=np.int64)
    member = np.zeros(max(int(values.max()) for values in nonempty) + 1, dtype=bool)
    for values in nonempty:
        member[values] = True
    return np.flatnonzero(member).astype(np.int64, copy=False)


def unique_inverse(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``np.unique(keys, return_inverse=True, return_counts=True)`` for non-negative integer
    ``keys`` (1-D): the sorted distinct keys, each key's index among them and their counts.

    Counted over the key range when it is at most :data:`DENSE_RANGE_FACTOR` times the
    number of keys (a voxel grid fitted to its points), sorted otherwise.
    """
    keys = np.asarray(keys)
    if keys.size == 0 or int(keys.max()) >= DENSE_RANGE_FACTOR * keys.size:
        distinct, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
        return distinct, inverse.ravel(), counts
    all_counts = np.bincount(keys)
    distinct = np.flatnonzero(all_counts)
    position = np.zeros(len(all_counts), dtype=np.int64)
    position[distinct] = np.arange(len(distinct))
    return distinct.astype(keys.dtype, copy=False), position[keys], all_counts[distinct]


def ranks(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(values, return_inverse=True)`` for small integers (labels from -1): the
    sorted distinct values and each value's index among them, counted over their range."""
    lowest = values.min(initial=0)
    distinct, inverse, _ = unique_inverse(values - lowest)
    return distinct + lowest, inverse


def positions(members: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Index of each of ``values`` in ``members`` (sorted distinct non-negative integers that
    hold every value): ``np.searchsorted(members, values)``, through a table over the range
    instead of a binary search per value."""
    if len(values) == 0:
        return np.zeros(0, dtype=np.int64)
    table = np.empty(int(members[-1]) + 1, dtype=np.int64)
    table[members] = np.arange(len(members))
    return table[values]
