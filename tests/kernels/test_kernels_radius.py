"""Fixed-radius counts and bounded nearest points through cells: equal to cKDTree's answers,
ties to the lowest row, edge cases and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from supportnode.kernels.radius import count_within, nearest_within


def _d2(points: np.ndarray, query: np.ndarray) -> np.ndarray:
    """(Q, N) squared distances summed x, y, z in order, as cKDTree sums them."""
    d = points[None, :, :] - query[:, None, :]
    out = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
    return out + d[..., 2] * d[..., 2] if points.shape[1] == 3 else out


def _cloud(rng: np.random.Generator, n: int, dims: int, step: float, offset: float) -> np.ndarray:
    """n points quantised to ``step`` (many equal distances, many exactly at a radius that is a
    multiple of the step), around ``offset`` metres."""
    return offset + np.round(rng.uniform(0.0, 0.3, (n, dims)) / step) * step


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(0, 150),
    m=st.integers(0, 40),
    dims=st.sampled_from([2, 3]),
    step=st.sampled_from([0.01, 0.025, 1e-4]),
    radius=st.sampled_from([0.0, 0.01, 0.02, 0.05, 0.3, 2.0]),
    offset=st.sampled_from([0.0, -7.3, 1e3]),
    seed=st.integers(0, 2**31),
)
def test_counts_and_nearest_equal_brute_force_and_the_kd_tree(
    n, m, dims, step, radius, offset, seed
):
    rng = np.random.default_rng(seed)
    pts = _cloud(rng, n, dims, step, offset)
    qry = np.concatenate([pts[: m // 2], _cloud(rng, m - m // 2, dims, step, offset)])
    counts = count_within(pts, qry, radius)
    dist, rows = nearest_within(pts, qry, radius)
    assert counts.dtype == np.int64 and rows.dtype == np.int64 and counts.shape == (len(qry),)
    if n == 0:
        assert (counts == 0).all() and (rows == -1).all() and np.isinf(dist).all()
        return
    d2 = _d2(pts, qry)
    np.testing.assert_array_equal(counts, (d2 <= radius * radius).sum(axis=1))
    tree = cKDTree(pts)
    if len(qry):
        np.testing.assert_array_equal(
            counts, tree.query_ball_point(qry, radius, return_length=True)
        )
    inside = d2 < radius * radius
    want = np.where(inside.any(axis=1), np.where(inside, d2, np.inf).argmin(axis=1), -1)
    np.testing.assert_array_equal(rows, want)  # argmin: the lowest row of equal distances
    hit = rows >= 0
    np.testing.assert_array_equal(dist[hit], np.sqrt(d2[hit, rows[hit]]))
    assert np.isinf(dist[~hit]).all()
    if len(qry):  # the same bound as the tree's: d < bound, found or not alike
        kd, _ = tree.query(qry, distance_upper_bound=radius)
        np.testing.assert_array_equal(np.isfinite(kd), hit)
        np.testing.assert_array_equal(kd[hit], dist[hit])


def test_one_point_far_queries_and_a_zero_radius():
    pts = np.array([[1.0, 2.0, 3.0]])
    far = np.array([[1e9, -1e9, 0.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0 + 1e-12]])
    assert count_within(pts, far, 0.0).tolist() == [0, 1, 0]
    _, rows = nearest_within(pts, far, 1e-6)
    assert rows.tolist() == [-1, 0, 0]


def test_a_wide_cloud_and_a_tiny_radius_keep_their_cells_in_range():
    """A 2 km cloud with 1 mm cells would number its cells past int64: wider cells, same
    answers."""
    pts = np.array([[0.0, 0.0, 0.0], [2000.0, 2000.0, 2000.0], [0.0005, 0.0, 0.0]])
    assert count_within(pts, pts, 0.001).tolist() == [2, 1, 2]
    assert nearest_within(pts, pts[:1] + 0.0001, 0.001)[1].tolist() == [0]


@pytest.mark.parametrize(
    ("points", "query", "radius", "message"),
    [
        (np.zeros((3, 4)), np.zeros((1, 3)), 0.1, r"points must be \(N, 2\) or \(N, 3\)"),
        (np.zeros((3, 3)), np.zeros(3), 0.1, "query must be"),
        (np.array([[0.0, np.nan, 0.0]]), np.zeros((1, 3)), 0.1, "points must be finite"),
        (np.zeros((1, 3)), np.array([[np.inf, 0.0, 0.0]]), 0.1, "query must be finite"),
        (np.zeros((1, 3)), np.zeros((1, 3)), -0.1, "radius must be finite and >= 0"),
        (np.zeros((1, 3)), np.zeros((1, 3)), np.nan, "radius must be finite and >= 0"),
    ],
)
def test_bad_input_is_a_one_line_error(points, query, radius, message):
    for fn in (count_within, nearest_within):
        with pytest.raises(ValueError, match=message):
            fn(points, query, radius)
