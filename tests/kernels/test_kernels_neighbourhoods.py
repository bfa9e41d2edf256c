"""Neighbourhood covariances against numpy's on the gathered neighbours, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels import runtime
from supportnode.kernels.neighbourhoods import _warm, neighbourhood_covariances

PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(1, 200),
    rows=st.integers(0, 50),
    k=st.integers(1, 12),
    seed=st.integers(0, 10_000),
)
def test_covariances_match_numpy(n, rows, k, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(0, 0.5, (n, 3))
    idx = rng.integers(0, n, (rows, k))
    got = neighbourhood_covariances(pts, idx)
    assert got.shape == (6, rows)
    for r in range(rows):
        cov = np.cov(pts[idx[r]].T, bias=True).reshape(3, 3)
        want = [cov[a, b] for a, b in PAIRS]
        np.testing.assert_allclose(got[:, r], want, rtol=1e-9, atol=1e-12)


def test_empty_query():
    assert neighbourhood_covariances(np.zeros((4, 3)), np.zeros((0, 5), np.int64)).shape == (6, 0)


def test_bad_input_is_rejected_before_the_loop():
    pts = np.zeros((4, 3))
    with pytest.raises(ValueError, match="shape"):
        neighbourhood_covariances(np.zeros((4, 2)), np.zeros((1, 3), np.int64))
    with pytest.raises(ValueError, match="lie in"):
        neighbourhood_covariances(pts, np.array([[0, 4]]))
    with pytest.raises(ValueError, match="k >= 1"):
        neighbourhood_covariances(pts, np.zeros(3, np.int64))
    pts[1, 2] = np.nan
    with pytest.raises(ValueError, match="finite"):
        neighbourhood_covariances(pts, np.array([[0, 1]]))


def test_warm_up_is_registered():
    assert _warm in runtime._WARMERS
    _warm()
