"""Per-label kernels: rows at given ranks (np.flatnonzero(labels == c)[ranks]), rows grouped by
label (a stable argsort and a gather)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels.groups import group_rows, label_boxes, rows_at_ranks, rows_by_key, run_sums


@settings(max_examples=80, deadline=None)
@given(m=st.integers(0, 400), n=st.integers(1, 12), seed=st.integers(0, 10_000))
def test_rows_are_the_ranked_rows_of_each_label(m, n, seed):
    rng = np.random.default_rng(seed)
    labels = rng.integers(-1, n, m)
    ranks, starts = [], [0]
    for c in range(n):
        count = int((labels == c).sum())
        # Any ascending ranks, some past the label's last row.
        want = np.unique(rng.integers(0, count + 2, rng.integers(0, 6)))
        ranks.extend(want.tolist())
        starts.append(len(ranks))
    got = rows_at_ranks(labels, np.array(ranks, np.int64), np.array(starts))
    for c in range(n):
        rows = np.flatnonzero(labels == c)
        want = np.array(ranks[starts[c] : starts[c + 1]], np.int64)
        padded = np.r_[rows, -1]  # a rank past the last row finds no row
        ref = padded[np.minimum(want, len(rows))]
        np.testing.assert_array_equal(got[starts[c] : starts[c + 1]], ref)


def test_labels_beyond_the_starts_and_int32_labels():
    labels = np.array([5, 0, -1, 0, 1, 0], np.int32)  # label 5 has no ranks: ignored
    got = rows_at_ranks(labels, np.array([0, 2, 0]), np.array([0, 2, 3]))
    np.testing.assert_array_equal(got, [1, 5, 4])


def test_bad_starts_are_refused():
    with pytest.raises(ValueError, match="starts must ascend"):
        rows_at_ranks(np.zeros(3, np.int64), np.array([0, 1]), np.array([0, 1]))
    with pytest.raises(ValueError, match="starts must ascend"):
        rows_at_ranks(np.zeros(3, np.int64), np.array([0, 1]), np.array([0, 2, 1]))


@settings(max_examples=60, deadline=None)
@given(m=st.integers(0, 300), n=st.integers(0, 8), seed=st.integers(0, 10_000))
def test_label_boxes_are_each_labels_min_and_max(m, n, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(m, 3))
    labels = rng.integers(-1, n + 2, m)  # labels n, n + 1 beyond the count: ignored
    lo, hi = label_boxes(pts, labels, n)
    assert lo.shape == hi.shape == (n, 3)
    for c in range(n):
        mine = pts[labels == c]
        if len(mine) == 0:
            assert np.isposinf(lo[c]).all() and np.isneginf(hi[c]).all()
        else:
            np.testing.assert_array_equal(lo[c], mine.min(axis=0))
            np.testing.assert_array_equal(hi[c], mine.max(axis=0))
    with pytest.raises(ValueError, match="labels"):
        label_boxes(pts, labels[:-1] if m else np.zeros(1, np.int64), n)


@settings(max_examples=80, deadline=None)
@given(m=st.integers(0, 300), n=st.integers(0, 10), seed=st.integers(0, 10_000))
def test_rows_grouped_as_a_stable_argsort_and_a_gather(m, n, seed):
    rng = np.random.default_rng(seed)
    labels = rng.integers(-1, n + 2, m)  # labels >= n are left out, as -1
    points = rng.normal(size=(m, 3))
    start, rows, grouped, lo, hi = group_rows(points, labels, n)
    inside = (labels >= 0) & (labels < n)
    order = np.argsort(np.where(inside, labels, -1), kind="stable")[int((~inside).sum()) :]
    np.testing.assert_array_equal(rows, order)
    np.testing.assert_array_equal(grouped, points[order])
    np.testing.assert_array_equal(
        start, np.r_[0, np.cumsum(np.bincount(labels[inside], minlength=n))]
    )
    for c in range(n):
        mine = points[labels == c]
        if len(mine):
            np.testing.assert_array_equal(lo[c], mine.min(axis=0))
            np.testing.assert_array_equal(hi[c], mine.max(axis=0))
        else:
            assert np.isinf(lo[c]).all() and np.isinf(hi[c]).all()
    with pytest.raises(ValueError, match="group_rows"):
        group_rows(points[:, :2].ravel(), labels, n)


@settings(max_examples=60, deadline=None)
@given(p=st.integers(0, 300), c=st.integers(0, 8), seed=st.integers(0, 10_000))
def test_run_sums_are_cumsums_last_rows_to_the_bit(p, c, seed):
    # Far from the origin and of mixed scale: the order of the additions shows in the bits.
    rng = np.random.default_rng(seed)
    points = rng.normal(0, 1, (p, 3)) * rng.uniform(1e-3, 1e3, (p, 1)) + 1e4
    begin = rng.integers(0, p + 1, c)
    end = np.minimum(begin + rng.integers(0, 50, c), p)
    got = run_sums(points, begin, end)
    for j in range(c):
        run = points[begin[j] : end[j]]
        want = np.cumsum(run, axis=0)[-1] if len(run) else np.zeros(3)
        np.testing.assert_array_equal(got[j], want)
    with pytest.raises(ValueError, match="within the rows"):
        run_sums(points, np.array([0]), np.array([p + 1]))


@settings(max_examples=60, deadline=None)
@given(
    m=st.integers(0, 300), n_lab=st.integers(0, 8), n=st.integers(0, 5), seed=st.integers(0, 10_000)
)
def test_rows_by_key_as_a_stable_argsort_of_the_keys(m, n_lab, n, seed):
    # free_space_all's grouping: each label's key (the last entry: label -1's), keys 0..n-1.
    rng = np.random.default_rng(seed)
    labels = rng.integers(-1, n_lab, m).astype(np.int32)
    key_of = rng.integers(0, n + 2, n_lab + 1).astype(np.int32)
    rows, start = rows_by_key(labels, key_of, n)
    key = key_of[labels]
    on = np.flatnonzero(key < n)
    by_key = np.argsort(key[on], kind="stable")
    np.testing.assert_array_equal(rows, on[by_key])
    np.testing.assert_array_equal(start, np.searchsorted(key[on][by_key], np.arange(n + 1)))


def test_rows_by_key_refuses_labels_without_a_key():
    with pytest.raises(ValueError, match="no key"):
        rows_by_key(np.array([0, 3]), np.array([0, 0]), 1)
    rows, start = rows_by_key(np.zeros(0, np.int64), np.array([0]), 2)
    assert len(rows) == 0 and start.tolist() == [0, 0, 0]
