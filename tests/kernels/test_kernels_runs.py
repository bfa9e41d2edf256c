"""Run moments and range extremes against numpy reductions over gathered points, bad input."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels import runtime
from supportnode.kernels.runs import (
    _warm,
    label_runs,
    labelled,
    newly_labelled,
    range_extremes,
    run_moments,
    scatter_lookup,
)

PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 300), k=st.integers(0, 200), seed=st.integers(0, 10_000))
def test_run_moments_match_numpy_reductions(n, k, seed):
    rng = np.random.default_rng(seed)
    local = [rng.uniform(0, 0.1, n) for _ in range(3)]
    idx = np.sort(rng.integers(0, n, k))
    run = np.flatnonzero(np.r_[True, rng.random(max(k - 1, 0)) < 0.2]) if k else np.zeros(0, int)
    sums, outer, lo, hi = run_moments(local, idx, run)
    assert sums.shape == (len(run), 3) and outer.shape == (len(run), 6)
    bounds = np.append(run, k)
    for r in range(len(run)):
        pts = np.stack([c[idx[bounds[r] : bounds[r + 1]]] for c in local], axis=1)
        np.testing.assert_allclose(sums[r], pts.sum(axis=0), rtol=1e-12, atol=1e-15)
        want = [np.sum(pts[:, a] * pts[:, b]) for a, b in PAIRS]
        np.testing.assert_allclose(outer[r], want, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(lo[r], pts.min(axis=0))  # exact: no rounding
        np.testing.assert_array_equal(hi[r], pts.max(axis=0))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 200), seed=st.integers(0, 10_000))
def test_range_extremes_match_numpy(n, seed):
    rng = np.random.default_rng(seed)
    local = [rng.normal(0, 1, n) for _ in range(3)]
    cuts = np.sort(rng.integers(0, n + 1, 6))
    starts, counts = cuts[0::2], cuts[1::2] - cuts[0::2]
    lo, hi = range_extremes(local, starts, counts)
    for r, (s, c) in enumerate(zip(starts, counts, strict=True)):
        if c == 0:
            assert (lo[r] == np.inf).all() and (hi[r] == -np.inf).all()
            continue
        pts = np.stack([col[s : s + c] for col in local], axis=1)
        np.testing.assert_array_equal(lo[r], pts.min(axis=0))
        np.testing.assert_array_equal(hi[r], pts.max(axis=0))


def test_empty_input():
    cols = [np.zeros(0)] * 3
    out = run_moments(cols, np.zeros(0, np.int64), np.zeros(0, np.int64))
    assert [a.shape for a in out] == [(0, 3), (0, 6), (0, 3), (0, 3)]
    lo, hi = range_extremes(cols, np.zeros(0, np.int64), np.zeros(0, np.int64))
    assert lo.shape == hi.shape == (0, 3)


def test_bad_input_is_rejected_before_the_loop():
    cols = [np.zeros(4)] * 3
    with pytest.raises(ValueError, match="lie in"):
        run_moments(cols, np.array([0, 4]), np.array([0]))
    with pytest.raises(ValueError, match="increase"):
        run_moments(cols, np.array([0, 1]), np.array([0, 0]))
    with pytest.raises(ValueError, match="without runs"):
        run_moments(cols, np.array([0, 1]), np.zeros(0, np.int64))
    with pytest.raises(ValueError, match="one length"):
        run_moments([np.zeros(4), np.zeros(3), np.zeros(4)], np.array([0]), np.array([0]))
    with pytest.raises(ValueError, match="outside"):
        range_extremes(cols, np.array([2]), np.array([3]))


def test_warm_up_is_registered():
    assert _warm in runtime._WARMERS
    _warm()


@settings(max_examples=80, deadline=None)
@given(n_vox=st.integers(0, 30), seed=st.integers(0, 10_000))
def test_labelled_matches_numpy(n_vox, seed):
    # Voxels of 1 to 20 points tiling the labels (a grid's order), some labelled, some not.
    rng = np.random.default_rng(seed)
    counts = rng.integers(1, 21, n_vox)
    starts = np.cumsum(counts) - counts
    labels = rng.integers(-1, 4, int(counts.sum())).astype(np.int32)
    labels[rng.random(len(labels)) < rng.uniform(0, 1)] = -1
    at, vox, per, last = labelled(labels, starts, counts)
    want = np.flatnonzero(labels >= 0)
    np.testing.assert_array_equal(at, want)
    np.testing.assert_array_equal(vox, np.repeat(np.arange(n_vox), counts)[want])
    np.testing.assert_array_equal(per, np.bincount(vox, minlength=n_vox))
    for v in range(n_vox):
        mine = labels[starts[v] : starts[v] + counts[v]]
        on = mine[mine >= 0]
        assert last[v] == (on[-1] if len(on) else -1)


def test_labelled_edges_and_bad_ranges():
    at, vox, per, last = labelled(np.zeros(0, np.int32), np.zeros(0, int), np.zeros(0, int))
    assert len(at) == len(vox) == len(per) == len(last) == 0
    at, vox, per, last = labelled(np.array([5]), np.array([0]), np.array([1]))
    assert at.tolist() == [0] and vox.tolist() == [0] and per.tolist() == [1]
    assert last.tolist() == [5]
    at, _, per, last = labelled(np.array([-1, -1]), np.array([0]), np.array([2]))
    assert len(at) == 0 and per.tolist() == [0] and last.tolist() == [-1]
    with pytest.raises(ValueError, match="tile"):
        labelled(np.zeros(3, np.int32), np.array([0, 1]), np.array([1, 1]))
    with pytest.raises(ValueError, match="tile"):
        labelled(np.zeros(3, np.int32), np.array([0, 2]), np.array([1, 2]))
    with pytest.raises(ValueError, match="length"):
        labelled(np.zeros(3, np.int32), np.array([0]), np.array([1, 2]))


@settings(max_examples=80, deadline=None)
@given(n_vox=st.integers(0, 30), share=st.floats(0, 1), seed=st.integers(0, 10_000))
def test_label_runs_match_numpy(n_vox, share, seed):
    # The numpy reduction it replaced: voxels whose points are all labelled alike are pure;
    # in the others, runs of one label among the labelled points, voxel by voxel.
    rng = np.random.default_rng(seed)
    counts = rng.integers(1, 16, n_vox)
    starts = np.cumsum(counts) - counts
    labels = rng.integers(0, 3, int(counts.sum())).astype(np.int32)
    labels[rng.random(len(labels)) < share] = -1
    whole = rng.random(n_vox) < 0.5  # voxels of one label throughout
    for v in np.flatnonzero(whole):
        labels[starts[v] : starts[v] + counts[v]] = rng.integers(0, 3)
    pure, present, idx, run, run_lab, run_vox = label_runs(labels, starts, counts)
    at = np.flatnonzero(labels >= 0)
    lab = labels[at].astype(np.int64)
    np.testing.assert_array_equal(present, np.bincount(lab) if len(at) else np.zeros(0, int))
    at_vox = np.repeat(np.arange(n_vox), counts)[at]
    want_pure = np.zeros(n_vox, bool)
    for v in range(n_vox):
        mine = labels[starts[v] : starts[v] + counts[v]]
        want_pure[v] = (mine >= 0).all() and len(set(mine.tolist())) == 1
    np.testing.assert_array_equal(pure, want_pure)
    mixed = ~want_pure[at_vox]
    np.testing.assert_array_equal(idx, at[mixed])
    g, vox = lab[mixed], at_vox[mixed]
    cut = np.r_[True, (vox[1:] != vox[:-1]) | (g[1:] != g[:-1])] if len(g) else np.zeros(0, bool)
    want_run = np.flatnonzero(cut)
    np.testing.assert_array_equal(run, want_run)
    np.testing.assert_array_equal(run_lab, g[want_run])
    np.testing.assert_array_equal(run_vox, vox[want_run])


def test_label_runs_edges():
    pure, present, idx, run, *_ = label_runs(
        np.zeros(0, np.int32), np.zeros(0, int), np.zeros(0, int)
    )
    assert len(pure) == len(present) == len(idx) == len(run) == 0
    pure, present, idx, run, run_lab, run_vox = label_runs(np.array([2, -1, 2]), [0], [3])
    assert run_vox.tolist() == [0]
    assert pure.tolist() == [False] and present.tolist() == [0, 0, 2]
    assert idx.tolist() == [0, 2] and run.tolist() == [0] and run_lab.tolist() == [2]
    pure, present, idx, *_ = label_runs(np.array([1, 1]), [0], [2])
    assert pure.tolist() == [True] and present.tolist() == [0, 2] and len(idx) == 0
    with pytest.raises(ValueError, match="tile"):
        label_runs(np.zeros(3, np.int32), np.array([1]), np.array([3]))


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 300), n_min=st.integers(0, 8), seed=st.integers(0, 10_000))
def test_newly_labelled_counts_the_changed_points_of_the_ranges(n, n_min, seed):
    rng = np.random.default_rng(seed)
    before = rng.integers(-1, 5, n).astype(np.int32)
    labels = before.copy()
    cuts = np.unique(np.r_[0, np.sort(rng.integers(0, n + 1, 6)), n])
    ranges = [(a, b - a) for a, b in itertools.pairwise(cuts)]
    chosen = [r for r in ranges if rng.random() < 0.6]
    for a, c in chosen:  # only the chosen ranges change
        labels[a : a + c] = np.where(rng.random(c) < 0.5, rng.integers(-1, 7, c), labels[a : a + c])
    starts = np.array([a for a, _ in chosen], np.int64)
    counts = np.array([c for _, c in chosen], np.int64)
    got = newly_labelled(labels, before, starts, counts, n_min)
    want = np.bincount(labels[(labels >= 0) & (before < 0)], minlength=n_min)
    np.testing.assert_array_equal(got, want)


def test_newly_labelled_refuses_ranges_outside():
    lab = np.zeros(3, np.int32)
    with pytest.raises(ValueError, match="outside"):
        newly_labelled(lab, lab, np.array([2]), np.array([2]), 1)
    assert newly_labelled(lab, lab, np.zeros(0, int), np.zeros(0, int), 2).tolist() == [0, 0]


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 200), n_lut=st.integers(1, 6), seed=st.integers(0, 10_000))
def test_scatter_lookup_is_numpys_scatter_of_a_gather(n, n_lut, seed):
    rng = np.random.default_rng(seed)
    lut = rng.integers(-1, 9, n_lut).astype(np.int32)
    idx = rng.integers(-n_lut, n_lut, n).astype(np.int32)  # -1: the last entry, as numpy's
    rows = rng.permutation(n + 5)[:n]
    got = np.full(n + 5, -7, np.int32)
    want = got.copy()
    scatter_lookup(got, rows, lut, idx)
    want[rows] = lut[idx]
    np.testing.assert_array_equal(got, want)


def test_scatter_lookup_refuses_positions_outside_and_writes_nothing():
    out = np.zeros(3, np.int32)
    with pytest.raises(ValueError, match="outside"):
        scatter_lookup(out, np.array([0, 3]), np.array([5], np.int32), np.array([0, 0]))
    with pytest.raises(ValueError, match="outside"):
        scatter_lookup(out, np.array([0, 1]), np.array([5], np.int32), np.array([0, 1]))
    assert out.tolist() == [0, 0, 0]
    with pytest.raises(ValueError, match="one length"):
        scatter_lookup(out, np.array([0]), np.array([5], np.int32), np.array([0, 1]))
