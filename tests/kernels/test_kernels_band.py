"""The band kernels: column sums, points in flagged columns and band rows against numpy."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels.band import (
    band_rows,
    column_sums,
    label_voxel_counts,
    points_in_columns,
)


def _grid(seed: int, voxels: int, per_voxel: int, surfaces: int):
    rng = np.random.default_rng(seed)
    counts = rng.integers(1, per_voxel + 1, voxels)
    starts = np.r_[0, np.cumsum(counts)[:-1]].astype(np.int64)
    n = int(counts.sum())
    size = np.array([0.03, 0.02, 0.03])
    local = [rng.uniform(0, size[a], n) for a in range(3)]
    local[0][: n // 4] = 0.0  # on the voxel's lower edge
    labels = rng.integers(-1, surfaces, n)
    use = rng.random(surfaces) < 0.7
    return starts, counts, local, size, labels, use, rng.normal(size=n)


def _reference(starts, counts, local, size, labels, use, value, per):
    n = len(labels)
    vox = np.repeat(np.arange(len(starts)), counts)
    at = np.flatnonzero((labels >= 0) & use[np.maximum(labels, 0)])
    li = np.minimum((local[0][at] / size[0] * per[0]).astype(np.int64), per[0] - 1)
    lj = np.minimum((local[1][at] / size[1] * per[1]).astype(np.int64), per[1] - 1)
    key = (vox[at] * per[0] + li) * per[1] + lj
    keys = len(starts) * per[0] * per[1]
    comp = np.full(len(starts), -1)
    comp[vox[at]] = labels[at]
    assert n == len(value)
    return at, key, np.bincount(key, minlength=keys), np.bincount(key, value[at], keys), comp


@settings(max_examples=60, deadline=None)
@given(
    voxels=st.integers(1, 30),
    per_voxel=st.integers(1, 12),
    surfaces=st.integers(1, 4),
    per=st.tuples(st.integers(1, 4), st.integers(1, 4)),
    seed=st.integers(0, 10_000),
)
def test_columns_match_numpy(voxels, per_voxel, surfaces, per, seed):
    starts, counts, local, size, labels, use, value = _grid(seed, voxels, per_voxel, surfaces)
    per = np.array(per)
    at, key, n_ref, total_ref, comp_ref = _reference(
        starts, counts, local, size, labels, use, value, per
    )
    n, total, comp = column_sums(starts, counts, local, size, labels, use, value, per)
    np.testing.assert_array_equal(n, n_ref)
    np.testing.assert_allclose(total, total_ref, atol=1e-12)
    np.testing.assert_array_equal(comp, comp_ref)
    flagged = np.random.default_rng(seed).random(len(n)) < 0.3
    got = points_in_columns(starts, counts, local, size, labels, use, flagged, per)
    np.testing.assert_array_equal(got, at[flagged[key]])


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 80), surfaces=st.integers(1, 4), seed=st.integers(0, 10_000))
def test_band_rows_match_numpy(n, surfaces, seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1, 1, (n, 3))
    labels = rng.integers(-1, surfaces, n)
    use = rng.random(surfaces) < 0.7
    always = rng.random(n) < 0.1
    lo, hi = np.array([-0.5, -0.2]), np.array([0.3, 0.6])
    inside = np.all((pts[:, :2] >= lo) & (pts[:, :2] <= hi), axis=1)
    want = np.flatnonzero((labels >= 0) & use[np.maximum(labels, 0)] & (inside | always))
    np.testing.assert_array_equal(band_rows(pts, labels, use, lo, hi, always), want)
    everywhere = band_rows(pts, labels, use, np.full(2, -np.inf), np.full(2, np.inf), always)
    np.testing.assert_array_equal(
        everywhere, np.flatnonzero((labels >= 0) & use[np.maximum(labels, 0)])
    )


def test_bad_input_is_refused():
    starts, counts, local, size, labels, use, value = _grid(0, 3, 4, 2)
    with pytest.raises(ValueError, match="no entry in use"):
        column_sums(starts, counts, local, size, labels, use[:1], value, np.array([2, 2]))
    with pytest.raises(ValueError, match="outside the points"):
        column_sums(starts, counts + 5, local, size, labels, use, value, np.array([2, 2]))
    with pytest.raises(ValueError, match="one entry per column"):
        points_in_columns(
            starts, counts, local, size, labels, use, np.ones(3, bool), np.array([2, 2])
        )
    with pytest.raises(ValueError, match="match in length"):
        band_rows(
            np.zeros((2, 3)), np.zeros(3, np.int64), use, np.zeros(2), np.ones(2), np.zeros(2, bool)
        )


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 400),
    n_comp=st.integers(1, 6),
    n_vox=st.integers(1, 40),
    dense=st.booleans(),
    seed=st.integers(0, 10_000),
)
def test_label_voxel_counts_are_bincounts(n, n_comp, n_vox, dense, seed):
    rng = np.random.default_rng(seed)
    labels = rng.integers(-1, n_comp, n).astype(np.int32)
    at = np.flatnonzero(labels >= 0)
    vox = np.sort(rng.integers(0, n_vox, len(at)))
    count, w = label_voxel_counts(labels, at, vox, n_comp, n_vox, dense)
    comp = labels[at].astype(np.int64)
    np.testing.assert_array_equal(count, np.bincount(comp, minlength=n_comp))
    if dense:
        flat = comp * n_vox + vox
        np.testing.assert_array_equal(w, np.bincount(flat, minlength=n_comp * n_vox))
    else:
        assert len(w) == 0


def test_label_voxel_counts_refuse_a_label_past_n_comp():
    labels = np.array([0, 3, 1], np.int32)
    assert label_voxel_counts(labels, np.arange(3), np.zeros(3, int), 2, 1, True) is None
    count, w = label_voxel_counts(labels[:1], np.arange(1), np.zeros(1, int), 1, 1, True)
    assert count.tolist() == [1] and w.tolist() == [1]
