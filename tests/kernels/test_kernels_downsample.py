"""Voxel moments and axis support kernels against plain numpy, NaN rows, bad input."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels.downsample import voxel_moments
from supportnode.kernels.orientation import axis_support


def _reference(points: np.ndarray, size: float) -> dict[tuple, tuple]:
    """Count, centroid and covariance per voxel key, by numpy grouping."""
    pts = points[np.isfinite(points).all(axis=1)]
    keys = np.floor(pts / size).astype(np.int64)
    out = {}
    for key in {tuple(k) for k in keys}:
        q = pts[(keys == key).all(axis=1)]
        c = np.cov(q.T, bias=True).reshape(3, 3)
        out[key] = (len(q), q.mean(axis=0), c[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]])
    return out


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 400),
    size=st.sampled_from([0.05, 0.3, 1.0]),
    offset=st.floats(-1e4, 1e4),
    seed=st.integers(0, 10_000),
)
def test_moments_match_numpy_grouping(n, size, offset, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(offset, 1.0, (n, 3))
    pts[rng.random(n) < 0.1] = np.nan  # missing pixels of an organised cloud
    counts, centroids, covs = voxel_moments(pts, size)
    want = _reference(pts, size)
    assert len(counts) == len(want) and counts.sum() == np.isfinite(pts).all(axis=1).sum()
    for cnt, cen, cov in zip(counts, centroids, covs, strict=True):
        key = tuple(np.floor(cen / size).astype(np.int64))
        w_cnt, w_cen, w_cov = want[key]
        assert cnt == w_cnt
        np.testing.assert_allclose(cen, w_cen, rtol=0, atol=1e-9 * (1 + abs(offset)))
        np.testing.assert_allclose(cov, w_cov, rtol=0, atol=1e-9)


def _sums_in_order(points: np.ndarray, size: float) -> np.ndarray:
    """The kernel's sums (V, 13), voxel by first point, each added point by point in order
    (first point, offsets' sums, products' sums, count): what the bits must be."""
    rows: dict[tuple, list[float]] = {}
    inv = 1.0 / size
    for x, y, z in points.tolist():
        f = (x * inv, y * inv, z * inv)
        if not all(abs(c) < 2.0**52 for c in f):
            continue
        row = rows.setdefault(tuple(int(np.floor(c)) for c in f), [x, y, z] + [0.0] * 10)
        dx, dy, dz = x - row[0], y - row[1], z - row[2]
        for q, term in enumerate((dx, dy, dz, dx * dx, dy * dy, dz * dz, dx * dy, dx * dz,
                                  dy * dz, 1.0)):  # fmt: skip
            row[3 + q] += term
    return np.array(list(rows.values())).reshape(-1, 13)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 3000), runs=st.booleans(), seed=st.integers(0, 10_000))
def test_sums_are_added_point_by_point_in_order(n, runs, seed):
    from supportnode.kernels.downsample import _sums

    rng = np.random.default_rng(seed)
    pts = rng.normal(rng.uniform(-100, 100), rng.uniform(0.01, 3.0), (n, 3))
    if runs:  # an image's neighbouring pixels: runs of one voxel, voxels seen again
        pts = pts[np.argsort(np.floor(pts[:, 0] / 0.05), kind="stable")]
    pts[rng.random(n) < 0.05] = np.nan
    want = _sums_in_order(pts, 0.05)
    got = _sums(np.ascontiguousarray(pts), 1.0 / 0.05)
    assert got.shape == want.shape and np.array_equal(got, want)


def test_many_voxels_grow_the_table_and_keep_first_seen_order():
    pts = np.column_stack([np.arange(5000) * 0.1 + 0.05, np.zeros(5000), np.zeros(5000)])
    counts, centroids, _ = voxel_moments(pts, 0.1)  # 5000 voxels: the table grows 3 times
    assert (counts == 1).all()
    np.testing.assert_allclose(centroids, pts)


def test_nan_inf_and_huge_rows_are_skipped():
    pts = np.array([[0.01, 0.0, 0.0], [np.nan, 0, 0], [np.inf, 0, 0], [1e300, 0, 0], [0.02, 0, 0]])
    counts, centroids, _ = voxel_moments(pts, 0.05)
    assert counts.tolist() == [2]
    np.testing.assert_allclose(centroids, [[0.015, 0.0, 0.0]])
    assert voxel_moments(np.full((3, 3), np.nan), 0.05)[0].shape == (0,)


@pytest.mark.parametrize(
    ("points", "size", "message"),
    [
        (np.zeros((4, 2)), 0.1, r"\(N, 3\)"),
        (np.zeros((4, 3)), 0.0, "positive"),
        (np.zeros((4, 3)), np.nan, "positive"),
    ],
)
def test_moments_bad_input(points, size, message):
    with pytest.raises(ValueError, match=message):
        voxel_moments(points, size)


def test_axis_support_counts_both_signs_within_the_cone():
    rng = np.random.default_rng(0)
    normals = rng.normal(size=(500, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    axes = normals[:50]
    cos = np.cos(np.radians(10.0))
    want = (np.abs(axes @ normals.T) >= cos).sum(axis=1)
    np.testing.assert_array_equal(axis_support(axes, normals, cos), want)
    np.testing.assert_array_equal(axis_support(axes, -normals, cos), want)
    with pytest.raises(ValueError, match="finite"):
        axis_support(np.array([[np.nan, 0, 1.0]]), normals, cos)
    with pytest.raises(ValueError, match=r"\(K, 3\)"):
        axis_support(axes[:, :2], normals, cos)
