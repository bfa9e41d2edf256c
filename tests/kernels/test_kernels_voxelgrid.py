"""The dense voxel grid kernel against brute-force grouping, the numpy sort path, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.errors import InputError
from supportnode.geometry.voxels import _voxelize_sorted, voxelize
from supportnode.kernels import runtime
from supportnode.kernels.voxelgrid import _warm, group_dense, voxel_bounds


def _extent(pts: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lo, hi, bad = voxel_bounds(pts, size)
    assert bad == 0
    return lo.astype(np.int64), (hi - lo).astype(np.int64) + 1


def _reference(pts: np.ndarray, size: np.ndarray) -> dict[str, np.ndarray]:
    """The grid by sorting and grouping in plain numpy: keys lexicographic, points stable."""
    q = np.floor(pts / size)
    k = q.astype(np.int64)
    order = np.lexsort((k[:, 2], k[:, 1], k[:, 0]))  # stable: input order within a voxel
    keys, first, voxel, counts = np.unique(
        k[order], axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    point_voxel = np.empty(len(pts), np.int64)
    point_voxel[order] = voxel.ravel()
    local = (pts - q * size)[order]
    sums = np.zeros((len(keys), 3))
    np.add.at(sums, voxel.ravel(), local)
    prods = np.stack(
        [local[:, a] * local[:, b] for a, b in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))], 1
    )
    outer = np.zeros((len(keys), 6))
    np.add.at(outer, voxel.ravel(), prods)
    return dict(
        keys=keys,
        counts=counts,
        point_voxel=point_voxel,
        order=order,
        starts=first,
        local=local.T,
        sums=sums,
        outer=outer,
    )


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(1, 300),
    size=st.sampled_from([(0.1, 0.1, 0.05), (0.3, 0.3, 0.3), (1.0, 0.5, 0.02)]),
    spread=st.sampled_from([0.05, 1.0, 5.0]),
    offset=st.floats(-1e9, 1e9),
    seed=st.integers(0, 10_000),
)
def test_grid_matches_brute_force_grouping(n, size, spread, offset, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(offset, spread, (n, 3))
    if n > 3:
        pts[1::4] = pts[0]  # repeated points: one voxel, input order kept
    sz = np.asarray(size)
    keys, counts, pv, order, starts, local, sums, outer = group_dense(pts, sz, *_extent(pts, sz))
    want = _reference(pts, sz)
    for name, got in dict(
        keys=keys, counts=counts, point_voxel=pv, order=order, starts=starts, local=local
    ).items():
        np.testing.assert_array_equal(got, want[name], err_msg=name)  # exact, bit for bit
    np.testing.assert_allclose(sums, want["sums"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(outer, want["outer"], rtol=1e-12, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 2000), seed=st.integers(0, 10_000))
def test_voxelize_equals_the_sorting_path(n, seed):
    """The counting kernel and the numpy radix-sort path give one grid (moments to rounding)."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-3, 3, (n, 3))
    size = np.array([0.1, 0.1, 0.05])
    grid = voxelize(pts, size)
    origin, dims = _extent(pts, size)
    ref = _voxelize_sorted(pts, size, origin, dims, int(np.prod(dims)) - 1)
    for name in ("keys", "counts", "point_voxel", "order", "starts"):
        np.testing.assert_array_equal(getattr(grid, name), getattr(ref, name), err_msg=name)
    for a in range(3):
        np.testing.assert_array_equal(grid.local[a], ref.local[a])
    np.testing.assert_allclose(grid.sums, ref.sums, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(grid.outer, ref.outer, rtol=1e-12, atol=1e-12)


def test_empty_and_one_voxel():
    size = np.array([0.1, 0.1, 0.1])
    out = group_dense(np.zeros((0, 3)), size, np.zeros(3, np.int64), np.ones(3, np.int64))
    assert [len(a) for a in out] == [0, 0, 0, 0, 0, 3, 0, 0] and out[5].shape == (3, 0)
    assert voxelize(np.zeros((0, 3)), size).counts.shape == (0,)
    pts = np.array([[0.01, 0.02, 0.03], [0.05, 0.05, 0.05]])
    keys, counts, _, order, _, _, sums, _ = group_dense(
        pts, size, np.zeros(3, np.int64), np.ones(3, np.int64)
    )
    assert keys.tolist() == [[0, 0, 0]] and counts.tolist() == [2] and order.tolist() == [0, 1]
    np.testing.assert_allclose(sums[0], pts.sum(axis=0))


def test_keys_far_from_the_origin_stay_exact():
    """Keys near 2^39 (the limit is 2^40): offsets from the voxel corner keep their precision."""
    size = np.array([0.1, 0.1, 0.1])
    base = (2.0**39 - 3) * 0.1
    pts = base + np.array([[0.0, 0.0, 0.0], [0.15, 0.0, 0.0], [0.0, 0.25, 0.05]])
    grid = voxelize(pts, size)
    assert len(grid.counts) == 3
    assert grid.keys.min() >= 2**39 - 4 and grid.keys.max() < 2**39
    assert all((c >= -1e-3).all() and (c < 0.1 + 1e-3).all() for c in grid.local)
    with pytest.raises(InputError, match="too far"):
        voxelize(np.array([[2.0**41 * 0.1, 0, 0]]), size)


def test_nan_and_out_of_extent_are_rejected_before_the_loops():
    size = np.array([0.1, 0.1, 0.1])
    pts = np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0], [0.0, np.inf, 0.0]])
    assert voxel_bounds(pts, size)[2] == 2
    with pytest.raises(InputError, match="2 of 3 points are not finite"):
        voxelize(pts, size)
    origin, dims = np.zeros(3, np.int64), np.ones(3, np.int64)
    with pytest.raises(ValueError, match="not finite or lies outside"):
        group_dense(pts, size, origin, dims)
    with pytest.raises(ValueError, match="outside"):
        group_dense(np.array([[0.25, 0.0, 0.0]]), size, origin, dims)
    with pytest.raises(ValueError, match="shape"):
        group_dense(np.zeros((4, 2)), size, origin, dims)
    with pytest.raises(ValueError, match="voxel size"):
        group_dense(np.zeros((1, 3)), np.array([0.1, 0.0, 0.1]), origin, dims)
    with pytest.raises(ValueError, match="dims"):
        group_dense(np.zeros((1, 3)), size, origin, np.array([1, 0, 1]))


def test_warm_up_is_registered():
    assert _warm in runtime._WARMERS
    _warm()
