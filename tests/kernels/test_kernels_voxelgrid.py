"""The compiled voxelize against the numpy one, to the bit; its limits and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.errors import InputError
from supportnode.geometry.voxels import _voxelize_numpy, voxelize
from supportnode.kernels import runtime
from supportnode.kernels.voxelgrid import _warm, key_range

FIELDS = ("keys", "counts", "point_voxel", "sums", "outer", "order", "starts")


def _assert_same(a, b) -> None:
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert np.array_equal(x, y), name  # the same bits: no tolerance
    assert len(a.local) == len(b.local) == 3
    for x, y in zip(a.local, b.local, strict=True):
        assert np.array_equal(x, y)


@settings(max_examples=120, deadline=None)
@given(
    n=st.integers(1, 3000),
    spread=st.floats(0.001, 5.0),
    centre=st.floats(-1e4, 1e4),
    runs=st.booleans(),
    seed=st.integers(0, 10_000),
)
def test_compiled_voxelize_equals_numpy_bit_for_bit(n, spread, centre, runs, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(centre, spread, size=(n, 3))
    if runs:  # points grouped as a map or an image row hands them over
        pts = pts[np.argsort(np.floor(pts[:, 0] / 0.1), kind="stable")]
    size = rng.uniform(0.005, 0.3, 3)
    _assert_same(voxelize(pts, size), _voxelize_numpy(pts, size))


def test_long_runs_take_numpys_pairwise_halves():
    # Voxels of 1, 7, 8, 9, 128, 129, 1000 and 5000 points: each branch of the pairwise sum.
    rng = np.random.default_rng(1)
    parts = [rng.uniform(0, 0.05, (c, 3)) + [0.1 * i, 0, 0] for i, c in
             enumerate((1, 7, 8, 9, 128, 129, 1000, 5000))]  # fmt: skip
    pts = rng.permutation(np.concatenate(parts))
    size = np.array([0.1, 0.1, 0.1])
    got = voxelize(pts, size)
    assert sorted(got.counts.tolist()) == [1, 7, 8, 9, 128, 129, 1000, 5000]
    _assert_same(got, _voxelize_numpy(pts, size))


def test_one_point_and_a_sparse_box():
    one = np.array([[1.234, -5.0, 0.049]])
    size = np.array([0.1, 0.1, 0.05])
    g = voxelize(one, size)
    assert g.keys.tolist() == [[12, -50, 0]] and g.counts.tolist() == [1]
    _assert_same(g, _voxelize_numpy(one, size))
    # Two points a kilometre apart: too many possible keys for a counter each (the numpy
    # path sorts them), the same result.
    far = np.array([[0.0, 0.0, 0.0], [1000.0, 1000.0, 3.0]])
    _assert_same(voxelize(far, size), _voxelize_numpy(far, size))


def test_empty_and_bad_input():
    size = np.array([0.1, 0.1, 0.1])
    assert len(voxelize(np.zeros((0, 3)), size).counts) == 0
    with pytest.raises(InputError, match="finite"):
        voxelize(np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]]), size)
    with pytest.raises(InputError, match="finite"):
        voxelize(np.array([[0.0, 0.0, np.inf]]), size)
    with pytest.raises(InputError, match="too far from the origin"):
        voxelize(np.array([[0.0, 0.0, 0.0], [2.0**40 * 0.1, 0.0, 0.0]]), size)


def test_key_range_and_warm_up():
    lo, hi, finite = key_range(np.array([[0.05, -0.05, 0.0], [0.35, 0.2, -0.01]]),
                               np.array([0.1, 0.1, 0.1]))  # fmt: skip
    assert lo.tolist() == [0.0, -1.0, -1.0] and hi.tolist() == [3.0, 2.0, 0.0] and finite
    assert _warm in runtime._WARMERS


def test_signed_zeros_and_overflowing_keys():
    # -0.0 floors to -0.0, whose corner offset numpy computes as +0.0: the same sign here.
    pts = np.array([[-0.0, 0.0, -0.0], [0.0, -0.0, 0.01], [-5e-324, 0.02, 0.0]])
    size = np.array([0.1, 0.1, 2.0])
    got, want = voxelize(pts, size), _voxelize_numpy(pts, size)
    _assert_same(got, want)
    for x, y in zip(got.local, want.local, strict=True):
        assert np.array_equal(np.signbit(x), np.signbit(y))
    # Finite points whose keys overflow float64 are not finite keys.
    assert not key_range(np.array([[1e308, 0.0, 0.0]]), np.full(3, 1e-10))[2]
    lo, hi, finite = key_range(np.array([[0.05, -0.25, 0.0]]), np.array([-0.1, 0.1, 0.1]))
    assert lo.tolist() == [-1.0, -3.0, 0.0] and hi.tolist() == [-1.0, -3.0, 0.0] and finite
