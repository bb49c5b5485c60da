"""Percentiles of small 1-D samples at the cost of one partial sort, and a sort by two keys
at the cost of an unstable sort where no two elements tie in both.

The grasp planners take a few percentiles of a few hundred values for every candidate
(a jaw column's front and back, a band's extent across the closing line, a side's top
edge); ``np.percentile``'s general machinery (axes, methods, weights, NaN checks) then
costs several times the partial sort itself. :func:`percentile` returns what
``np.percentile(values, q)`` returns with its default ``"linear"`` method, bit for bit:
the same order statistics (which value sits at a sorted position does not depend on how
the sort gets there) interpolated with the same floating-point operations in the same
order (``a + (b - a) t``, or ``b - (b - a) (1 - t)`` for ``t >= 0.5``).
:func:`lexsort_pair` returns ``np.lexsort`` of two keys: where no two elements tie in
both, the sorted order is unique, and numpy's default sort finds it two to three times
faster than a stable sort on a few thousand values.
"""

from __future__ import annotations

import math

import numpy as np


def percentile(values: np.ndarray, q: float) -> float:
    """``float(np.percentile(values, q))`` for a 1-D float array without NaN and ``q`` in
    [0, 100]; NaN for an empty array."""
    return percentiles(values, (q,))[0]


def percentiles(values: np.ndarray, qs: tuple[float, ...]) -> tuple[float, ...]:
    """:func:`percentile` of ``values`` at each of ``qs``, with one partial sort."""
    n = len(values)
    if n == 0:
        return tuple(math.nan for _ in qs)
    positions = [(n - 1) * (q / 100) for q in qs]
    # Below the last position, a percentile lies between two neighbouring order statistics.
    inner = [math.floor(p) for p in positions if p < n - 1]
    kth = sorted({k for below in inner for k in (below, below + 1)} | {n - 1})
    ordered = np.partition(values, kth)
    found = []
    for position in positions:
        if position >= n - 1:
            found.append(float(ordered[n - 1]))
            continue
        below = math.floor(position)
        a, b = float(ordered[below]), float(ordered[below + 1])
        t = position - below
        difference = b - a
        found.append(b - difference * (1 - t) if t >= 0.5 else a + difference * t)
    return tuple(found)


def lexsort_pair(minor: np.ndarray, major: np.ndarray, major_bound: int) -> np.ndarray:
    """``np.lexsort((minor, major))``: the order that sorts by ``major`` (non-negative
    integers below ``major_bound``, 1-D), then by ``minor`` (floats without NaN, as long),
    what ties in both in their given order.

    Two sorts: by ``minor``, then stably by ``major`` (as 16-bit integers where they fit:
    numpy sorts those in one pass of counting). The first is numpy's default sort, whose
    order among equal values is arbitrary: where no two elements tie in both keys the
    sorted order is unique and it is the answer; else the first sort is done again
    stably."""
    numbers = major.astype(np.uint16) if major_bound <= np.iinfo(np.uint16).max + 1 else major
    by_minor = np.argsort(minor)
    order = by_minor[np.argsort(numbers[by_minor], kind="stable")]
    ordered_major, ordered_minor = major[order], minor[order]
    if np.any(
        (ordered_major[1:] == ordered_major[:-1]) & (ordered_minor[1:] == ordered_minor[:-1])
    ):
        by_minor = np.argsort(minor, kind="stable")
        order = by_minor[np.argsort(numbers[by_minor], kind="stable")]
    return order
