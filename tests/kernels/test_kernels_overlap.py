"""Shared footprint cells, compiled, against the numpy ranges it replaced; edge cases."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels import runtime
from supportnode.kernels.overlap import _warm, shared_cells


def _numpy_shared(a, b):
    """The trackers' numpy path: a search of a's cells in b's sorted ones, ranges expanded."""
    na, nb = len(a), len(b)
    size_a = np.array([len(x) for x in a])
    size_b = np.array([len(x) for x in b])
    ca, la = np.concatenate(a), np.repeat(np.arange(na), size_a)
    cb, lb = np.concatenate(b), np.repeat(np.arange(nb), size_b)
    order = np.argsort(cb, kind="stable")
    cb, lb = cb[order], lb[order]
    start = np.searchsorted(cb, ca, side="left")
    stop = np.searchsorted(cb, ca, side="right")
    n = stop - start
    rows = np.repeat(la, n)
    idx = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + np.repeat(start, n)
    return np.bincount(rows * nb + lb[idx], minlength=na * nb).reshape(na, nb)


def _footprints(rng, n, span):
    return [
        np.unique(rng.integers(-span, span, int(rng.integers(0, 60)))).astype(np.int64)
        for _ in range(n)
    ]


@settings(max_examples=100, deadline=None)
@given(na=st.integers(1, 12), nb=st.integers(1, 12), span=st.integers(1, 200),
       seed=st.integers(0, 10_000))  # fmt: skip
def test_shared_cells_equal_the_numpy_ranges(na, nb, span, seed):
    rng = np.random.default_rng(seed)
    a, b = _footprints(rng, na, span), _footprints(rng, nb, span)
    got = shared_cells(a, b)
    assert got.dtype == np.int64 and got.shape == (na, nb)
    assert np.array_equal(got, _numpy_shared(a, b))


def test_stacked_footprints_and_empty_sides():
    # A cell in two footprints of b (stacked boards) counts for both; empty lists, empty
    # footprints and keys at int64's ends.
    big = np.iinfo(np.int64)
    a = [np.array([big.min, 0, 5, big.max], np.int64), np.zeros(0, np.int64)]
    b = [np.array([0, 5], np.int64), np.array([5, big.max], np.int64), np.array([7])]
    assert shared_cells(a, b).tolist() == [[2, 2, 0], [0, 0, 0]]
    assert shared_cells([], b).shape == (0, 3) and shared_cells(a, []).shape == (2, 0)
    assert _warm in runtime._WARMERS
