"""The compiled support look-up against the numpy one it replaced; bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.geometry.objects.support_lookup import _SupportTable
from supportnode.kernels import runtime
from supportnode.kernels.lookup import _warm, table_lookup


def _numpy_lookup(table: _SupportTable, cp: np.ndarray) -> np.ndarray:
    """The look-up as numpy steps, as the package computed it before the kernel."""
    k = np.searchsorted(table.threshold, cp[:, 2], side="right")  # surfaces at or below
    i = np.floor(cp[:, 0] / table.cell[0]).astype(np.int64) - table.origin[0]
    j = np.floor(cp[:, 1] / table.cell[1]).astype(np.int64) - table.origin[1]
    _, h, w = table.best.shape
    outside = (i.astype(np.uint64) >= h) | (j.astype(np.uint64) >= w)
    # One flat gather for all points (those outside read cell 0, then get -1): 3x faster
    # than gathering k, i, j at the inside points and indexing the 3-D table with them.
    flat = (k * h + i) * w + j
    flat[outside] = 0
    sup = np.take(table.best.reshape(-1), flat).astype(np.int64)
    sup[outside] = -1
    return sup


@settings(max_examples=80, deadline=None)
@given(
    m=st.integers(0, 400),
    s=st.integers(0, 4),
    shape=st.tuples(st.integers(1, 30), st.integers(1, 30)),
    seed=st.integers(0, 10_000),
)
def test_lookup_matches_numpy(m, s, shape, seed):
    rng = np.random.default_rng(seed)
    cell = rng.uniform(0.02, 0.2, 2)
    origin = rng.integers(-20, 20, 2)
    best = rng.integers(-1, s + 1, (s + 1, *shape)).astype(np.int32)
    threshold = np.sort(rng.uniform(-1, 2, s))
    table = _SupportTable(cell, origin, best, threshold)
    span = (origin + np.array(shape) / 2) * cell
    cp = np.column_stack(
        [rng.normal(span, 2.0 * cell * np.array(shape), (m, 2)), rng.uniform(-1.5, 2.5, m)]
    )
    cp[: m // 5, 2] = np.resize(threshold, m // 5) if s else cp[: m // 5, 2]  # ties: side right
    assert np.array_equal(table.lookup(cp), _numpy_lookup(table, cp))


def test_bad_input_and_warm_up():
    best = np.zeros((2, 3, 3), np.int32)
    cp = np.zeros((1, 3))
    with pytest.raises(ValueError, match="S \\+ 1"):
        table_lookup(cp, np.zeros(2), np.ones(2), np.zeros(2), best)
    with pytest.raises(ValueError, match="ascend"):
        table_lookup(cp, np.array([1.0, 0.0]), np.ones(2), np.zeros(2), np.zeros((3, 3, 3)))
    assert _warm in runtime._WARMERS


def _percentile(a: np.ndarray, q: float) -> float:
    """``float(np.percentile(a, q))`` (method 'linear') of a non-empty 1-D float array: the same
    arithmetic, without the 40 us of numpy's generic quantile machinery per call."""
    n = len(a)
    v = (n - 1) * (q / 100)  # numpy's virtual index
    i = int(v) if v < n - 1 else -1  # floor; numpy's index -1 (the maximum) past the end
    # numpy's kth, not just (i, i + 1): equal values (0.0 and -0.0) then land alike.
    part = np.partition(a, np.unique([0, -1, i, i + 1 if i >= 0 else -1]))
    lo, hi = float(part[i]), float(part[i + 1 if i >= 0 else -1])
    t = v - i
    d = hi - lo
    # numpy's _lerp: from the nearer end, so t = 1 gives hi exactly.
    return hi - d * (1 - t) if t >= 0.5 else lo + d * t


@settings(max_examples=80, deadline=None)
@given(
    sizes=st.lists(st.integers(1, 700), min_size=0, max_size=12),
    band=st.floats(0.0, 0.05),
    seed=st.integers(0, 10_000),
)
def test_cluster_bottoms_match_numpy_percentile_and_mask(sizes, band, seed):
    from supportnode.kernels.lookup import cluster_bottoms

    rng = np.random.default_rng(seed)
    z = np.round(rng.normal(0.5, 0.2, sum(sizes)), 3)  # ties, as quantised depth has
    cuts = np.cumsum([0, *sizes])
    runs = rng.permutation(np.stack([cuts[:-1], cuts[1:]], axis=1)) if sizes else np.zeros((0, 2))
    bottom, n_low, rows = cluster_bottoms(z, runs, band)
    want_rows = []
    for k, (a, b) in enumerate(runs.astype(int)):
        part = z[a:b]
        want = _percentile(part, 1.0) if len(part) >= 100 else float(part.min())
        assert bottom[k] == want
        low = a + np.flatnonzero(part <= want + band)
        assert n_low[k] == len(low)
        want_rows.extend(low.tolist())
    assert rows.tolist() == want_rows


def test_cluster_bottoms_bad_input():
    from supportnode.kernels.lookup import cluster_bottoms

    with pytest.raises(ValueError, match="row ranges"):
        cluster_bottoms(np.zeros(4), np.array([[2, 2]]), 0.01)
    with pytest.raises(ValueError, match="row ranges"):
        cluster_bottoms(np.zeros(4), np.array([[0, 5]]), 0.01)
    with pytest.raises(ValueError, match="low percentile"):
        cluster_bottoms(np.zeros(4), np.array([[0, 4]]), 0.01, q=60.0)


@settings(max_examples=60, deadline=None)
@given(
    m=st.integers(0, 300),
    shape=st.tuples(st.integers(0, 12), st.integers(0, 12)),
    seed=st.integers(0, 10_000),
)
def test_lowest_per_cell_matches_numpy(m, shape, seed):
    from supportnode.kernels.lookup import lowest_per_cell

    rng = np.random.default_rng(seed)
    cell = rng.uniform(0.02, 0.2, 2)
    origin = rng.integers(-5, 5, 2)
    # Points inside and around the raster, on cell edges too.
    cp = np.column_stack(
        [
            (origin + rng.integers(-2, np.array(shape) + 2, (m, 2)) + rng.choice([0, 0.5], (m, 2)))
            * cell,
            np.round(rng.normal(0.5, 0.3, m), 2),
        ]
    )
    want = np.full(shape, np.inf)
    i = np.floor(cp[:, 0] / cell[0]).astype(np.int64) - origin[0]
    j = np.floor(cp[:, 1] / cell[1]).astype(np.int64) - origin[1]
    inside = (i >= 0) & (i < shape[0]) & (j >= 0) & (j < shape[1])
    np.minimum.at(want, (i[inside], j[inside]), cp[inside, 2])
    got = lowest_per_cell(cp, cell, origin, shape)
    assert got.shape == tuple(shape)
    np.testing.assert_array_equal(got, want)


def test_lowest_per_cell_bad_shape():
    from supportnode.kernels.lookup import lowest_per_cell

    with pytest.raises(ValueError, match="negative"):
        lowest_per_cell(np.zeros((1, 3)), np.ones(2), np.zeros(2), (-1, 2))


def _numpy_heights(cp, support, planes):
    """Each point's height above its surface's plane, NaN over none (the reference)."""
    h = np.full(len(cp), np.nan)
    ok = (support >= 0) & (support < len(planes))
    p = planes[support[ok]]
    h[ok] = cp[ok, 2] - (
        p[:, 2] + p[:, 3] * (cp[ok, 0] - p[:, 0]) + p[:, 4] * (cp[ok, 1] - p[:, 1])
    )
    return h


@settings(max_examples=60, deadline=None)
@given(m=st.integers(0, 200), s=st.integers(0, 4), seed=st.integers(0, 10_000))
def test_level_split_matches_numpy(m, s, seed):
    from supportnode.kernels.lookup import level_split

    rng = np.random.default_rng(seed)
    planes = np.column_stack([rng.normal(0, 1, (s, 3)), rng.normal(0, 0.2, (s, 2))])
    cp = rng.normal(0, 1, (m, 3))
    support = rng.integers(-1, s, m)
    rows = rng.permutation(10 * m + 1)[:m]
    if s and m:  # some points right at their plane's level, on the band's edges too
        on = (support >= 0) & (rng.random(m) < 0.5)
        p = planes[support[on]]
        cp[on, 2] = p[:, 2] + p[:, 3] * (cp[on, 0] - p[:, 0]) + p[:, 4] * (cp[on, 1] - p[:, 1])
        cp[on, 2] += rng.choice([0.0, 0.002, -0.0029, 0.01, 0.05], on.sum())
    if s:
        planes[rng.integers(0, s)] = np.nan  # a surface left out (a noise band)
    h = _numpy_heights(cp, support, planes)
    at = np.abs(h) <= 0.003
    kept, kept_cp, kept_support, low, level = level_split(cp, rows, support, planes, 0.003, 0.03)
    np.testing.assert_array_equal(level, np.flatnonzero(at))
    np.testing.assert_array_equal(kept, rows[~at])
    np.testing.assert_array_equal(kept_cp, cp[~at])
    np.testing.assert_array_equal(kept_support, support[~at])
    np.testing.assert_array_equal(low, np.flatnonzero(h[~at] <= 0.033))


def test_level_split_bad_input():
    from supportnode.kernels.lookup import level_split

    with pytest.raises(ValueError, match="differ"):
        level_split(np.zeros((3, 3)), np.arange(2), np.zeros(3), np.zeros((1, 5)), 0.003, 0.03)


@settings(max_examples=60, deadline=None)
@given(m=st.integers(0, 200), s=st.integers(0, 4), seed=st.integers(0, 10_000))
def test_level_points_matches_numpy(m, s, seed):
    from supportnode.kernels.lookup import level_points

    rng = np.random.default_rng(seed)
    planes = np.column_stack([rng.normal(0, 1, (s, 3)), rng.normal(0, 0.2, (s, 2))])
    cp = rng.normal(0, 1, (m, 3))
    if s and m:  # points at a plane's level, on the band's edges, two planes at once too
        near = rng.integers(0, s, m)
        on = rng.random(m) < 0.6
        p = planes[near[on]]
        cp[on, 2] = p[:, 2] + p[:, 3] * (cp[on, 0] - p[:, 0]) + p[:, 4] * (cp[on, 1] - p[:, 1])
        cp[on, 2] += rng.choice([0.0, 0.002, -0.0029, 0.01], on.sum())
        planes = np.vstack([planes, planes[:1]])  # the same plane twice
    if s:
        planes[rng.integers(0, len(planes))] = np.nan  # a surface left out (a noise band)
    want_rows, want_surf = [], []
    for p in range(m):
        for k in range(len(planes)):
            h = _numpy_heights(cp[p : p + 1], np.array([k]), planes)[0]
            if abs(h) <= 0.003:
                want_rows.append(p)
                want_surf.append(k)
    rows, surf = level_points(cp, planes, 0.003)
    np.testing.assert_array_equal(rows, np.array(want_rows, np.int64))
    np.testing.assert_array_equal(surf, np.array(want_surf, np.int64))


def test_level_points_of_no_plane_and_no_point():
    from supportnode.kernels.lookup import level_points

    rows, surf = level_points(np.zeros((0, 3)), np.zeros((2, 5)), 0.003)
    assert rows.shape == surf.shape == (0,)
    rows, surf = level_points(np.ones((3, 3)), np.full((1, 5), np.nan), 0.003)
    assert rows.shape == surf.shape == (0,)
    rows, surf = level_points(np.array([[5.0, 5.0, 1.0]]), np.array([[0, 0, 1.0, 0, 0]]), 0.0)
    assert rows.tolist() == [0] and surf.tolist() == [0]
