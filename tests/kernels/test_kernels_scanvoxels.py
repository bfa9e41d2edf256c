"""The compiled scan voxelizing against numpy (np.unique + np.bincount, which sums in input
order: the same bits), including empty input, one voxel and far from the origin."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.geometry.voxels import OUTER_INDEX
from supportnode.kernels.scanvoxels import scan_voxels
from supportnode.map import VoxelMap
from supportnode.params import MapParams


def _box(cols, size):
    k = [np.floor(c / size) for c in cols]
    lo = np.array([c.min() for c in k]) if len(cols[0]) else np.zeros(3)
    hi = np.array([c.max() for c in k]) if len(cols[0]) else np.zeros(3)
    return lo, hi - lo + 1.0


def _scratch(n, top):
    return np.zeros(top, bool), np.zeros(top, np.int64), np.zeros(n, np.int64), np.zeros((3, n))


def _reference(cols, size):
    k = np.stack([np.floor(c / size) for c in cols], axis=1)
    keys, inv = np.unique(k.astype(np.int64), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    local = [c - k[:, a] * size for a, c in enumerate(cols)]
    m = [np.bincount(inv, weights=local[a], minlength=len(keys)) for a in range(3)]
    m += [
        np.bincount(inv, weights=local[a] * local[b], minlength=len(keys)) for a, b in OUTER_INDEX
    ]
    return keys, inv, np.bincount(inv, minlength=len(keys)), np.stack(m, axis=1), local


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(1, 500),
    size=st.sampled_from([0.05, 0.2, 1.0]),
    offset=st.sampled_from([0.0, -3.3, 1e4]),
    spread=st.sampled_from([0.01, 1.0, 5.0]),
    seed=st.integers(0, 10_000),
)
def test_scan_voxels_matches_numpy_bit_for_bit(n, size, offset, spread, seed):
    rng = np.random.default_rng(seed)
    cols = [offset + rng.normal(0, spread, n) for _ in range(3)]
    lo, dims = _box(cols, size)
    top = int(np.prod(dims))
    if top > 1 << 22:
        return  # the map sorts such scans instead
    got = scan_voxels(cols, size, lo, dims, _scratch(n, top))
    want = _reference(cols, size)
    for g, w in zip(got[:4], want[:4], strict=True):
        assert np.array_equal(g, w)
    for g, w in zip(got[4], want[4], strict=True):
        assert np.array_equal(g, w)


def test_scan_voxels_one_voxel_and_the_mark_table_left_clear():
    cols = [np.array([0.01, 0.02, 0.03]), np.array([0.0, 0.01, 0.02]), np.array([1.0, 1.01, 1.02])]
    lo, dims = _box(cols, 0.05)
    scratch = _scratch(3, 8)
    keys, voxel, counts, moments, _local = scan_voxels(cols, 0.05, lo, dims, scratch)
    assert keys.tolist() == [[0, 0, 20]] and counts.tolist() == [3] and voxel.tolist() == [0, 0, 0]
    assert not scratch[0].any()  # ready for the next scan
    assert moments[0, 0] == pytest.approx(0.06)


def test_scan_voxels_empty_and_bad_input():
    e = np.zeros(0)
    keys, _voxel, _counts, moments, local = scan_voxels(
        [e, e, e], 0.05, np.zeros(3), np.ones(3), _scratch(0, 1)
    )
    assert keys.shape == (0, 3) and moments.shape == (0, 9) and len(local[0]) == 0
    with pytest.raises(ValueError, match="finite"):
        scan_voxels(
            [np.array([np.nan]), np.ones(1), np.ones(1)],
            0.05,
            np.zeros(3),
            np.ones(3),
            _scratch(1, 1),
        )
    with pytest.raises(ValueError, match="scratch"):
        scan_voxels([np.ones(2)] * 3, 0.05, np.zeros(3), np.full(3, 4.0), _scratch(2, 8))


@pytest.mark.parametrize("far", [False, True])
def test_the_map_voxelizes_alike_through_either_path(rng, far):
    """A room-sized scan goes through the compiled path, one with a far return (a box too
    large for a table) through numpy's sort: both equal the reference, bit for bit."""
    m = VoxelMap(MapParams())
    pts = rng.normal(0, 1.0, (3000, 3))
    if far:
        pts[0] = (400.0, -300.0, 50.0)
    cols = [np.ascontiguousarray(pts[:, a]) for a in range(3)]
    want = _reference(cols, m.size)
    grid = m._voxelize(cols)
    assert np.array_equal(grid.keys, want[0]) and np.array_equal(grid.voxel, want[1])
    assert np.array_equal(grid.counts, want[2]) and np.array_equal(grid.moments, want[3])
    assert all(np.array_equal(g, w) for g, w in zip(grid.local, want[4], strict=True))
