"""Percentiles of small samples against ``np.percentile``, and a sort by two keys against
``np.lexsort``: the oracles they must equal bit for bit (the planners' candidates depend
on them)."""

from __future__ import annotations

import math

import numpy as np

from pipeline.planning.order_statistics import lexsort_pair, percentile, percentiles


def test_percentiles_equal_numpy_bit_for_bit_on_random_samples_with_ties():
    rng = np.random.default_rng(41)
    for trial in range(400):
        values = rng.normal(0.1, 0.05, size=int(rng.integers(1, 300)))
        if trial % 2:
            values = np.round(values, 3)  # ties, as a cloud's quantised depths have
        for q in (0.0, 1.0, 2.0, 37.5, 50.0, 98.0, 99.0, 100.0):
            assert percentile(values, q) == float(np.percentile(values, q))
        pair = percentiles(values, (2.0, 98.0))
        assert pair == tuple(float(v) for v in np.percentile(values, [2.0, 98.0]))


def test_a_hand_computed_percentile_and_an_empty_sample():
    # Position (5 - 1) 0.3 = 1.2 between the sorted 2 and 4: 2 + 0.2 (4 - 2).
    assert math.isclose(percentile(np.array([8.0, 2.0, 4.0, 1.0, 16.0]), 30.0), 2.4)
    assert math.isnan(percentile(np.array([]), 50.0))


def test_lexsort_pair_equals_numpy_lexsort_with_and_without_ties():
    rng = np.random.default_rng(43)
    for trial in range(150):
        n = int(rng.integers(0, 2000))
        minor = rng.normal(0.0, 0.05, size=n)
        bound = 70_000 if trial % 5 == 4 else 200  # beyond 16 bits, as some calls have
        major = rng.integers(0, bound, size=n)
        if trial % 3 == 1:
            minor = np.round(minor, 2)  # many ties, in both keys
        elif trial % 3 == 2 and n > 1:
            minor[-1], major[-1] = minor[0], major[0]  # one tie in both
        assert np.array_equal(lexsort_pair(minor, major, bound), np.lexsort((minor, major)))
