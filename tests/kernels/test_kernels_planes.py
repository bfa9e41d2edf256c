"""Point labels by per-run planes: the kernel against numpy's vectorised rule, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels import runtime
from supportnode.kernels.planes import _warm, label_by_planes


def _reference(local, first, count, plane, label, tol, labels, best, nearer):
    """The rule as numpy's vectorised form (the planar method's before the kernel)."""
    lx, ly, lz = local
    a, bx, by = plane
    labels, best = labels.copy(), best.copy()
    pos = np.concatenate([np.arange(f, f + c) for f, c in zip(first, count, strict=True)] or [[]])
    pos = pos.astype(np.int64)
    rep = [np.repeat(x, count) for x in (a, bx, by, tol, label)]
    residual = lz[pos] - (rep[0] + rep[1] * lx[pos] + rep[2] * ly[pos])
    dist = np.abs(residual)
    better = dist <= rep[3]
    if nearer:
        seen = np.flatnonzero(better & (labels[pos] >= 0))
        better[seen] = dist[seen] < np.abs(best[pos[seen]])
    at = pos[better]
    labels[at] = rep[4][better]
    best[at] = residual[better]
    return labels, best


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(0, 300),
    runs=st.integers(0, 12),
    nearer=st.booleans(),
    tol=st.sampled_from([0.0, 0.01, 0.05]),
    seed=st.integers(0, 10_000),
)
def test_labels_match_the_vectorised_rule_bit_for_bit(n, runs, nearer, tol, seed):
    rng = np.random.default_rng(seed)
    local = [rng.uniform(0, 0.1, n), rng.uniform(0, 0.1, n), rng.normal(0.02, 0.03, n)]
    # Non-overlapping runs over the points (some points in none), in any order.
    cuts = np.sort(rng.integers(0, n + 1, 2 * runs))
    first, count = cuts[0::2], cuts[1::2] - cuts[0::2]
    perm = rng.permutation(runs)
    first, count = first[perm], count[perm]
    plane = (rng.normal(0.02, 0.02, runs), rng.normal(0, 0.2, runs), rng.normal(0, 0.2, runs))
    label = rng.integers(0, 5, runs)
    tols = np.full(runs, tol) * rng.uniform(0.5, 1.5, runs)
    labels = np.where(rng.random(n) < 0.3, rng.integers(0, 5, n), -1).astype(np.int32)
    best = np.where(labels >= 0, rng.uniform(-0.05, 0.05, n), np.nan)
    want_labels, want_best = _reference(
        local, first, count, plane, label, tols, labels, best, nearer
    )
    label_by_planes(local, first, count, plane, label, tols, labels, best, nearer)
    np.testing.assert_array_equal(labels, want_labels)
    on = labels >= 0
    np.testing.assert_array_equal(best[on], want_best[on])


def test_empty_runs_and_points_leave_labels_alone():
    labels, best = np.full(3, -1, np.int32), np.zeros(3)
    e, ei = np.zeros(0), np.zeros(0, np.int64)
    cols = [np.zeros(3)] * 3
    label_by_planes(cols, ei, ei, (e, e, e), ei, e, labels, best, False)
    assert labels.tolist() == [-1, -1, -1]
    e3 = [np.zeros(0)] * 3
    label_by_planes(e3, ei, ei, (e, e, e), ei, e, np.zeros(0, np.int32), np.zeros(0), True)


def test_bad_input_is_rejected_before_the_loop():
    cols = [np.zeros(2), np.zeros(2), np.zeros(2)]
    one = np.zeros(1)
    run = np.zeros(1, np.int64), np.full(1, 2, np.int64)
    labels, best = np.full(2, -1, np.int32), np.zeros(2)
    with pytest.raises(ValueError, match="finite"):
        label_by_planes(cols, *run, (np.full(1, np.nan), one, one), one, one, labels, best, False)
    with pytest.raises(ValueError, match="outside"):
        label_by_planes(cols, run[0], np.full(1, 3), (one, one, one), one, one, labels, best, False)
    with pytest.raises(ValueError, match="int32"):
        label_by_planes(cols, *run, (one, one, one), one, one, np.full(2, -1), best, False)
    with pytest.raises(ValueError, match="one length"):
        label_by_planes(cols, *run, (one, one, one), one, one, labels, np.zeros(3), False)
    assert labels.tolist() == [-1, -1]


def test_warm_up_is_registered():
    assert _warm in runtime._WARMERS
    _warm()


def _random_runs(n: int, runs: int, seed: int) -> tuple:
    """n points' local columns, ``runs`` runs over them (first, count) and a plane each
    (rel (runs, 3), slopes bx, by, tolerance tol)."""
    rng = np.random.default_rng(seed)
    local = [rng.uniform(0, 0.1, n), rng.uniform(0, 0.1, n), rng.normal(0.02, 0.01, n)]
    cuts = np.sort(rng.integers(0, n + 1, 2 * runs))
    first, count = cuts[0::2], cuts[1::2] - cuts[0::2]
    rel = rng.normal(0.03, 0.02, (runs, 3))
    bx, by, tol = rng.normal(0, 0.1, runs), rng.normal(0, 0.1, runs), rng.uniform(0, 0.02, runs)
    return local, first, count, rel, bx, by, tol


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 300), runs=st.integers(0, 12), seed=st.integers(0, 10_000))
def test_plane_inliers_count_as_numpys_vectorised_test(n, runs, seed):
    from supportnode.kernels.planes import plane_inliers

    local, first, count, rel, bx, by, tol = _random_runs(n, runs, seed)
    got = plane_inliers(local, first, count, rel, (bx, by), tol)
    pos = np.concatenate([np.arange(f, f + c) for f, c in zip(first, count, strict=True)] or [[]])
    pos = pos.astype(np.int64)
    off = [local[a][pos] - np.repeat(rel[:, a], count) for a in range(3)]
    dist = np.abs(off[0] * np.repeat(bx, count) + off[1] * np.repeat(by, count) + off[2])
    inlier = (dist <= np.repeat(tol, count)).astype(np.int64)
    starts = np.cumsum(count) - count
    want = np.array([inlier[s : s + c].sum() for s, c in zip(starts, count, strict=True)])
    np.testing.assert_array_equal(got, want.astype(np.int64).reshape(-1))


def test_plane_inliers_refuse_runs_outside_the_points():
    from supportnode.kernels.planes import plane_inliers

    cols = [np.zeros(2)] * 3
    one = np.zeros(1)
    with pytest.raises(ValueError, match="outside"):
        plane_inliers(cols, np.zeros(1), np.full(1, 3), np.zeros((1, 3)), (one, one), one)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 300), runs=st.integers(0, 12), seed=st.integers(0, 10_000))
def test_inlier_moments_match_numpy_over_the_inliers(n, runs, seed):
    from supportnode.kernels.planes import inlier_moments, plane_inliers

    local, first, count, rel, bx, by, tol = _random_runs(n, runs, seed)
    lo, hi, sums, outer = inlier_moments(local, first, count, rel, (bx, by), tol)
    n_in = plane_inliers(local, first, count, rel, (bx, by), tol)
    assert lo.shape == hi.shape == (runs, 2) and sums.shape == (runs, 3)
    for p in range(runs):
        idx = np.arange(first[p], first[p] + count[p])
        o = np.stack([local[a][idx] - rel[p, a] for a in range(3)], axis=1)
        o = o[np.abs(o[:, 0] * bx[p] + o[:, 1] * by[p] + o[:, 2]) <= tol[p]]
        assert len(o) == n_in[p]  # the same points as plane_inliers counts
        if len(o) == 0:
            assert (lo[p] == np.inf).all() and (hi[p] == -np.inf).all()
            assert (sums[p] == 0).all() and (outer[p] == 0).all()
            continue
        np.testing.assert_array_equal(lo[p], o[:, :2].min(axis=0))
        np.testing.assert_array_equal(hi[p], o[:, :2].max(axis=0))
        np.testing.assert_allclose(sums[p], o.sum(axis=0), rtol=1e-12, atol=1e-15)
        want = [
            (o[:, a] * o[:, b]).sum() for a, b in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
        ]
        np.testing.assert_allclose(outer[p], want, rtol=1e-12, atol=1e-15)


def test_inlier_moments_refuse_runs_outside_the_points():
    from supportnode.kernels.planes import inlier_moments

    cols = [np.zeros(2)] * 3
    one = np.zeros(1)
    with pytest.raises(ValueError, match="outside"):
        inlier_moments(cols, np.zeros(1), np.full(1, 3), np.zeros((1, 3)), (one, one), one)
    with pytest.raises(ValueError, match="one length"):
        inlier_moments(cols, np.zeros(2), np.ones(2), np.zeros((1, 3)), (one, one), one)
