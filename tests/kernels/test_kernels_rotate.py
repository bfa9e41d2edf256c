"""The compiled cloud transform gives transform_points' values, float32 or float64."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.geometry.transform import transform_points
from supportnode.kernels.rotate import transform_points_fast


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 300),
    f32=st.booleans(),
    shift=st.booleans(),
    scale=st.sampled_from([1e-3, 1.0, 1e4]),
    seed=st.integers(0, 10_000),
)
def test_same_values_as_transform_points(n, f32, shift, scale, seed):
    rng = np.random.default_rng(seed)
    pts = (rng.normal(0, scale, (n, 3))).astype(np.float32 if f32 else np.float64)
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    translation = rng.normal(0, scale, 3) if shift else None
    got = transform_points_fast(pts, rotation, translation)
    assert got.dtype == np.float64 and got.shape == (n, 3)
    np.testing.assert_array_equal(got, transform_points(pts, rotation, translation))


def test_non_finite_points_stay_non_finite():
    pts = np.array([[np.nan, 0.0, 0.0], [np.inf, 1.0, 0.0], [1.0, 2.0, 3.0]])
    got = transform_points_fast(pts, np.eye(3))
    with np.errstate(invalid="ignore"):  # inf * 0 is NaN, in numpy as in the kernel
        np.testing.assert_array_equal(got, transform_points(pts, np.eye(3)))
