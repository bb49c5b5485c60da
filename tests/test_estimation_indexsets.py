"""Index sets without sorting (pipeline.estimation.indexsets) against numpy's set routines."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.estimation.indexsets import ranks, union, unique_inverse


@pytest.mark.parametrize("sizes", [(0,), (0, 0), (5,), (300, 0, 40), (1, 1000, 7)])
def test_union_is_numpys_sorted_union(sizes):
    rng = np.random.default_rng(len(sizes))
    arrays = [rng.integers(0, 500, size) for size in sizes]
    expected = np.unique(np.concatenate(arrays)) if arrays else np.empty(0, dtype=np.int64)
    got = union(*arrays)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("high", [1, 50, 10_000, 10**9])
def test_unique_inverse_is_numpys_on_dense_and_sparse_keys(high):
    # high = 1 and 50 take the counting path, 10**9 the sorting one.
    keys = np.random.default_rng(high).integers(0, high, 2_000)
    distinct, inverse, counts = unique_inverse(keys)
    expected = np.unique(keys, return_inverse=True, return_counts=True)
    for got, want in zip((distinct, inverse, counts), expected, strict=True):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(distinct[inverse], keys)


def test_unique_inverse_of_nothing():
    distinct, inverse, counts = unique_inverse(np.empty(0, dtype=np.int64))
    assert distinct.size == inverse.size == counts.size == 0


def test_ranks_are_numpys_unique_with_inverse_from_minus_one():
    labels = np.random.default_rng(3).integers(-1, 80, 5_000)
    distinct, inverse = ranks(labels)
    expected = np.unique(labels, return_inverse=True)
    np.testing.assert_array_equal(distinct, expected[0])
    np.testing.assert_array_equal(inverse, expected[1])
