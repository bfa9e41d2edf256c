"""The map crop: the rows in a box against numpy, giving up at the limit, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels.crop import crop_rows


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(0, 200),
    limit=st.integers(0, 250),
    f32=st.booleans(),
    seed=st.integers(0, 10_000),
)
def test_crop_matches_numpy(n, limit, f32, seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1, 1, (n, 3)).astype(np.float32 if f32 else np.float64)
    pts[: n // 5, :2] = 0.25  # on the box's bound: inside
    lo, hi = np.array([-0.3, -0.5]), np.array([0.25, 0.4])
    inside = np.flatnonzero(np.all((pts[:, :2] >= lo) & (pts[:, :2] <= hi), axis=1))
    got = crop_rows(pts, lo, hi, limit)
    if len(inside) >= limit:
        assert got is None
    else:
        np.testing.assert_array_equal(got, inside)


def test_crop_of_an_empty_map_and_a_bad_box():
    assert crop_rows(np.zeros((0, 3)), np.zeros(2), np.ones(2), 0) is None
    assert crop_rows(np.zeros((0, 3)), np.zeros(2), np.ones(2), 1).shape == (0,)
    with pytest.raises(ValueError, match="NaN"):
        crop_rows(np.zeros((2, 3)), np.array([0.0, np.nan]), np.ones(2), 5)
    open_box = crop_rows(np.ones((3, 3)), np.full(2, -np.inf), np.full(2, np.inf), 5)
    np.testing.assert_array_equal(open_box, [0, 1, 2])
