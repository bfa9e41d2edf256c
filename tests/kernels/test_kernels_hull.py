"""The compiled footprint hulls are Qhull's hulls, ring for ring, for many clusters at once."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull, QhullError

from supportnode.kernels.hull import footprint_hulls


def reference_ring(xy: np.ndarray) -> np.ndarray:
    """Qhull's ring from the lowest x (then y); the distinct points, or a line's two ends,
    for degenerate sets."""
    uniq = np.unique(xy, axis=0)
    try:
        ring = ConvexHull(xy).vertices
    except (QhullError, ValueError):
        if len(uniq) <= 2:
            return uniq
        return uniq[[0, -1]]  # collinear: the lexicographic ends are the line's ends
    first = np.lexsort((xy[ring, 1], xy[ring, 0]))[0]
    return xy[np.roll(ring, -first)]


def rings(points: np.ndarray, begin, end) -> list[np.ndarray]:
    rows, starts = footprint_hulls(points, np.asarray(begin), np.asarray(end))
    return [points[rows[a:b], :2] for a, b in itertools.pairwise(starts)]


@settings(max_examples=80, deadline=None)
@given(
    sizes=st.lists(st.integers(0, 80), min_size=0, max_size=6),
    kind=st.sampled_from(["normal", "grid", "line", "float32"]),
    seed=st.integers(0, 10_000),
)
def test_rings_are_qhulls(sizes, kind, seed):
    """Random, gridded (duplicates, collinear edges), collinear and float32 points; empty and
    one-point clusters; clusters given in any order of their rows."""
    rng = np.random.default_rng(seed)
    n = sum(sizes)
    if kind == "grid":
        pts = np.round(rng.uniform(0, 4, (n, 3)))
    elif kind == "line":
        t = rng.integers(0, 64, n) / 8.0  # exactly on the line, in binary
        pts = np.c_[1.0 + 2.0 * t, -3.0 * t, rng.uniform(0, 1, n)]
    else:
        pts = rng.normal(0, 2.0, (n, 3))
        if kind == "float32":
            pts = pts.astype(np.float32).astype(np.float64)
    end = np.cumsum(sizes).astype(np.int64)
    begin = end - np.asarray(sizes, dtype=np.int64)
    order = rng.permutation(len(sizes))
    got = rings(pts, begin[order], end[order])
    for k, c in enumerate(order):
        xy = pts[begin[c] : end[c], :2]
        if len(xy) == 0:
            assert got[k].shape == (0, 2)
            continue
        np.testing.assert_array_equal(got[k], reference_ring(xy))


def test_big_clusters_keep_every_vertex():
    """Most points of a disc are filtered before the chain; the hull keeps all rim points."""
    rng = np.random.default_rng(1)
    a = rng.uniform(0, 2 * np.pi, 500)
    rim = np.c_[np.cos(a), np.sin(a), np.zeros(500)]
    inner = np.c_[rng.uniform(-0.6, 0.6, (50_000, 2)), np.zeros(50_000)]
    pts = np.concatenate([inner, rim])
    (ring,) = rings(pts, [0], [len(pts)])
    assert len(ring) == 500
    np.testing.assert_array_equal(ring, reference_ring(pts[:, :2]))


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_a_ring_of_walls_is_thinned_and_keeps_its_hull(noise):
    """Most of a room's wall points lie outside the octagon of its extremes: the hull of a
    sample of them drops the rest before the sort, and the ring stays Qhull's."""
    rng = np.random.default_rng(5)
    t = rng.uniform(0, 1, 40_000)
    side = rng.integers(0, 4, 40_000)
    x = np.select([side == 0, side == 1, side == 2], [t * 4, np.full_like(t, 4.0), t * 4], 0.0)
    y = np.select(
        [side == 0, side == 1, side == 2], [np.zeros_like(t), t * 3, np.full_like(t, 3.0)], t * 3
    )
    pts = np.c_[x + rng.normal(0, noise, len(t)), y + rng.normal(0, noise, len(t)), t]
    pts = np.round(pts, 3)  # lidar columns: repeated x, y
    (ring,) = rings(pts, [0], [len(pts)])
    np.testing.assert_array_equal(ring, reference_ring(pts[:, :2]))


def test_single_and_repeated_points():
    pts = np.array([[1.0, 2.0, 0.0], [1.0, 2.0, 5.0], [1.0, 2.0, 1.0], [0.0, 0.0, 0.0]])
    same, single, pair = rings(pts, [0, 3, 2], [3, 4, 4])
    np.testing.assert_array_equal(same, [[1.0, 2.0]])
    np.testing.assert_array_equal(single, [[0.0, 0.0]])
    np.testing.assert_array_equal(pair, [[0.0, 0.0], [1.0, 2.0]])


def test_rows_outside_the_points_are_refused():
    pts = np.zeros((4, 3))
    with pytest.raises(ValueError, match="within the points"):
        footprint_hulls(pts, np.array([0]), np.array([5]))
    with pytest.raises(ValueError, match="within the points"):
        footprint_hulls(pts, np.array([3]), np.array([2]))
    with pytest.raises(ValueError, match="points"):
        footprint_hulls(np.zeros(4), np.array([0]), np.array([1]))
