"""Dense-grid occupancy against the numpy steps it replaced; bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels import runtime
from supportnode.kernels.occupancy import _warm, grid_keys, occupied_voxels


def _numpy_keys(cp, size):
    ijk = [((c - c.min()) / size).astype(np.int64) + 1 for c in cp.T]
    dims = np.array([c.max() + 2 for c in ijk], dtype=np.int64)
    return (ijk[0] * dims[1] + ijk[1]) * dims[2] + ijk[2], dims


@settings(max_examples=80, deadline=None)
@given(m=st.integers(1, 500), size=st.floats(0.005, 0.2), seed=st.integers(0, 10_000))
def test_occupancy_matches_the_numpy_steps(m, size, seed):
    rng = np.random.default_rng(seed)
    cp = rng.normal(rng.uniform(-50, 50, 3), rng.uniform(0.01, 1.0), (m, 3))
    support = rng.integers(-1, 4, m)
    keys, dims = grid_keys(cp, size)
    want_keys, want_dims = _numpy_keys(cp, size)
    assert np.array_equal(keys, want_keys) and np.array_equal(dims, want_dims)
    cells = int(np.prod(dims))
    vkeys, occupied, vid, of_point, vsup = occupied_voxels(keys, cells, support)
    assert np.array_equal(vkeys, np.unique(keys))
    assert np.array_equal(np.flatnonzero(occupied), vkeys)
    assert np.array_equal(vid[vkeys], np.arange(len(vkeys)))
    assert np.array_equal(vkeys[of_point], keys)
    want = np.full(len(vkeys), -1)
    np.maximum.at(want, of_point, support)
    assert np.array_equal(vsup, want)
    assert occupied_voxels(keys, cells)[4] is None
    # the border: no occupied voxel on the grid's faces
    ijk = np.stack(np.unravel_index(vkeys, tuple(dims)), axis=1)
    assert ijk.min() >= 1 and (ijk <= dims - 2).all()


def test_bad_input_and_warm_up():
    with pytest.raises(ValueError, match=r"keys must lie in \[0, 4\)"):
        occupied_voxels(np.array([0, 4]), 4)
    with pytest.raises(ValueError, match="one id per point"):
        occupied_voxels(np.array([0, 1]), 4, np.array([0]))
    assert _warm in runtime._WARMERS
