"""The map's kept-point filling against a plain per-voxel reference; bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels import runtime
from supportnode.kernels.places import _warm, fill_places


def _reference(slots, counts, starts, local, keys, size, raw, pts, raw_n):
    k = raw.shape[1]
    for s, c, a in zip(slots, counts, starts, strict=True):
        take = min(c, k - raw_n[s])
        for j in range(max(take, 0)):
            pick = a + j * c // take
            off = np.array([col[pick] for col in local], np.float32)
            raw[s, raw_n[s] + j] = off
            pts[s, raw_n[s] + j] = keys[s] * size + off.astype(np.float64)
        raw_n[s] += max(take, 0)


@settings(max_examples=80, deadline=None)
@given(v=st.integers(0, 40), k=st.integers(1, 6), seed=st.integers(0, 10_000))
def test_fill_places_matches_a_per_voxel_reference(v, k, seed):
    rng = np.random.default_rng(seed)
    store = v + 5
    slots = rng.permutation(store)[:v]
    counts = rng.integers(0, 12, v)
    starts = np.cumsum(counts) - counts
    local = [rng.uniform(0, 0.05, int(counts.sum())) for _ in range(3)]
    keys = rng.integers(-1000, 1000, (store, 3))
    raw_n = rng.integers(0, k + 1, store).astype(np.int32)  # some voxels already full
    raw = rng.uniform(0, 0.05, (store, k, 3)).astype(np.float32)
    pts = rng.uniform(-50, 50, (store, k, 3))
    want = [a.copy() for a in (raw, pts, raw_n)]
    had = raw_n.copy()
    _reference(slots, counts, starts, local, keys, 0.05, *want)
    filled = fill_places(slots, counts, starts, local, keys, 0.05, raw, pts, raw_n)
    for got, ref in zip((raw, pts, raw_n), want, strict=True):
        assert np.array_equal(got, ref)
    assert filled == int(np.sum((counts > 0) & (had[slots] < k)))


def test_bad_input_and_warm_up():
    raw = np.zeros((2, 4, 3), np.float32)
    args = (np.zeros(1, np.int64), np.ones(1, np.int64), np.zeros(1, np.int64), [np.zeros(1)] * 3)
    with pytest.raises(ValueError, match="float32"):
        fill_places(*args, np.zeros((2, 3), np.int64), 0.05, raw.astype(np.float64),
                    np.zeros((2, 4, 3)), np.zeros(2, np.int32))  # fmt: skip
    with pytest.raises(ValueError, match="one length"):
        fill_places(np.zeros(2, np.int64), *args[1:], np.zeros((2, 3), np.int64), 0.05, raw,
                    np.zeros((2, 4, 3)), np.zeros(2, np.int32))  # fmt: skip
    assert _warm in runtime._WARMERS


@settings(max_examples=60, deadline=None)
@given(s=st.integers(0, 200), k=st.integers(1, 6), seed=st.integers(0, 10_000))
def test_kept_points_match_the_mask_and_gather(s, k, seed):
    from supportnode.kernels.places import kept_points

    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(s, k, 3))
    raw_n = rng.integers(0, k + 1, s).astype(np.int32)
    have = np.arange(k) < raw_n[:, None]
    want = np.take(pts.reshape(-1, 3), np.flatnonzero(have), axis=0)
    got = kept_points(pts, raw_n)
    assert got.shape == (int(raw_n.sum()), 3) and np.array_equal(got, want)


def test_kept_points_bad_input():
    from supportnode.kernels.places import kept_points

    with pytest.raises(ValueError, match=r"raw_n must lie in \[0, 2\]"):
        kept_points(np.zeros((2, 2, 3)), np.array([0, 3], np.int32))
    with pytest.raises(ValueError, match="must be"):
        kept_points(np.zeros((2, 2)), np.array([0, 1], np.int32))


def _off_plane_numpy(raw, slots, raw_n, normal, level):
    """The renewal test's distances as the map computed them in numpy."""
    k = raw.shape[1]
    wide = raw[slots].astype(np.float64)
    dist = wide[:, :, 0] * normal[:, 0, None]
    dist += wide[:, :, 1] * normal[:, 1, None]
    dist += wide[:, :, 2] * normal[:, 2, None]
    dist -= level[:, None]
    np.abs(dist, out=dist)
    dist[np.arange(k)[None, :] >= raw_n[slots, None]] = 0.0
    most = dist[:, 0].copy() if len(slots) else np.zeros(0)
    for j in range(1, k):
        np.maximum(most, dist[:, j], out=most)
    return dist, most


@settings(max_examples=80, deadline=None)
@given(s=st.integers(1, 60), v=st.integers(0, 60), k=st.integers(1, 6), seed=st.integers(0, 9999))
def test_off_plane_matches_the_numpy_path(s, v, k, seed):
    from supportnode.kernels.places import off_plane

    rng = np.random.default_rng(seed)
    raw = rng.uniform(0, 0.05, (s, k, 3)).astype(np.float32)
    raw_n = rng.integers(0, k + 1, s).astype(np.int32)
    slots = rng.integers(0, s, v)
    normal = rng.normal(size=(v, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    level = rng.uniform(-0.05, 0.05, v)
    if v and seed % 7 == 0:
        normal[0] = np.nan  # a NaN plane: np.maximum's NaN propagates
    got = off_plane(raw, slots, raw_n, normal, level)
    want = _off_plane_numpy(raw, slots, raw_n, normal, level)
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape and np.array_equal(g, w, equal_nan=True)


def test_off_plane_bad_input():
    from supportnode.kernels.places import off_plane

    raw = np.zeros((2, 3, 3), np.float32)
    n32 = np.zeros(2, np.int32)
    with pytest.raises(ValueError, match="slots outside"):
        off_plane(raw, np.array([2]), n32, np.ones((1, 3)), np.zeros(1))
    with pytest.raises(ValueError, match="normal must be"):
        off_plane(raw, np.array([1]), n32, np.ones((2, 3)), np.zeros(1))
    with pytest.raises(ValueError, match="raw must be"):
        off_plane(raw[:, :, :2], np.array([1]), n32, np.ones((1, 3)), np.zeros(1))
