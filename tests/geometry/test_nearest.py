"""The detection's nearest-point queries and x, y hulls without scipy.spatial: the answers the
k-d tree and Qhull gave, ties to the lowest row, degenerate sets."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull, QhullError, cKDTree

from supportnode.geometry.nearest import nearest, neighbour_distances, within
from supportnode.geometry.objects.hull import footprint_area, footprint_equations, footprint_ring


def _d2(points: np.ndarray, query: np.ndarray) -> np.ndarray:
    d = points[None, :, :] - query[:, None, :]
    return (d * d).sum(axis=2)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 200),
    m=st.integers(0, 50),
    dims=st.sampled_from([2, 3]),
    shape=st.sampled_from(["spread", "line", "flat", "one spot", "quantised"]),
    seed=st.integers(0, 2**31),
)
def test_nearest_rows_and_distances_match_brute_force_and_the_kd_tree(n, m, dims, shape, seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-2.0, 2.0, (n, dims))
    if shape == "line":
        pts[:, 1:] = 0.5
    elif shape == "flat" and dims == 3:
        pts[:, 2] = 1.0
    elif shape == "one spot":
        pts[:] = pts[0]
    elif shape == "quantised":
        pts = np.round(pts / 0.05) * 0.05
    qry = np.concatenate([pts[: m // 2], rng.uniform(-3.0, 3.0, (m - m // 2, dims))])
    rows = nearest(pts, qry)
    d2 = _d2(pts, qry)
    np.testing.assert_array_equal(rows, d2.argmin(axis=1) if m else np.zeros(0, np.int64))
    if m:
        k = min(n, 2)
        want, _ = cKDTree(pts).query(qry, k=[k])
        np.testing.assert_allclose(neighbour_distances(pts, qry, k)[:, -1], want[:, 0], atol=0)


def test_within_is_strictly_closer_than_the_bound():
    pts = np.array([[0.0, 0.0], [1.0, 0.0]])
    qry = np.array([[0.5, 0.0], [0.5, 0.49], [3.0, 3.0]])
    assert within(pts, qry, 0.5).tolist() == [False, False, False]
    assert within(pts, qry, 0.5000001).tolist() == [True, False, False]
    assert within(pts, qry, 0.71).tolist() == [True, True, False]  # 0.7001 away


def test_nearest_refuses_k_beyond_the_points_and_bad_shapes():
    with pytest.raises(ValueError, match=r"k must lie in \[1, 2\]"):
        neighbour_distances(np.zeros((2, 3)), np.zeros((1, 3)), 3)
    with pytest.raises(ValueError, match="points must be"):
        nearest(np.zeros((2, 4)), np.zeros((1, 4)))


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 60), shape=st.sampled_from(["spread", "line", "one spot", "grid"]),
       seed=st.integers(0, 2**31))  # fmt: skip
def test_footprint_hull_gives_qhulls_area_and_facets(n, shape, seed):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1.0, 1.0, (n, 2)) + 10.0
    if shape == "line":
        xy[:, 1] = 2.0 * xy[:, 0]
    elif shape == "one spot" and n:
        xy[:] = xy[0]
    elif shape == "grid":
        xy = np.round(xy / 0.25) * 0.25
    ring = footprint_ring(xy)
    try:
        hull = ConvexHull(xy)
    except (QhullError, ValueError):
        assert ring is None  # no area: no hull, as Qhull raised
        return
    assert ring is not None
    assert footprint_area(ring) == pytest.approx(hull.volume, rel=1e-12, abs=1e-15)
    eq = footprint_equations(ring)
    np.testing.assert_allclose(np.linalg.norm(eq[:, :2], axis=1), 1.0, rtol=1e-12)
    # The same facets (Qhull's in its own order), and every point inside them all.
    mine = np.round(eq, 9)[np.lexsort(np.round(eq, 9).T)]
    qhull = np.round(hull.equations, 9)[np.lexsort(np.round(hull.equations, 9).T)]
    np.testing.assert_allclose(mine, qhull, atol=1e-8)
    assert (xy @ eq[:, :2].T + eq[:, 2] <= 1e-12).all()
