"""Exact k nearest neighbours through a grid: against brute force, edge cases, threads, bad
input."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels import runtime
from supportnode.kernels.knn import KnnGrid, _warm


def knn_grid(points: np.ndarray, query: np.ndarray, k: int, size: float) -> np.ndarray | None:
    """The k nearest rows of each query through a grid of ``size`` cells; None: declined."""
    grid = KnnGrid.build(points, size)
    return None if grid is None else grid.query(query, k)


def _brute(points: np.ndarray, query: np.ndarray, k: int) -> np.ndarray:
    """The k nearest rows by (squared distance, row), as the kernel orders them."""
    d2 = ((query[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    rows = np.arange(len(points))
    out = np.zeros((len(query), k), np.int64)
    for q, d in enumerate(d2):
        out[q] = np.lexsort((rows, d))[:k]
    return out


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(1, 120),
    m=st.integers(0, 30),
    k_frac=st.floats(0.0, 1.0),
    size=st.sampled_from([0.02, 0.07, 0.3, 5.0]),
    offset=st.sampled_from([0.0, 1e4]),
    dupes=st.booleans(),
    lattice=st.booleans(),
    seed=st.integers(0, 10_000),
)
def test_same_neighbours_as_brute_force(n, m, k_frac, size, offset, dupes, lattice, seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1, 1, (n, 3))
    if lattice:  # quantised coordinates, as depth images give: many equal distances
        pts = np.round(pts * 4) / 4
    pts += offset
    if dupes:
        pts[n // 2 :] = pts[: n - n // 2]  # every point twice: ties broken by row
    own = min(m // 2, n)  # some queries are points of the cloud, the others anywhere near
    query = np.concatenate([pts[:own], rng.uniform(-1.5, 1.5, (m - own, 3)) + offset])
    k = max(1, round(k_frac * n))
    got = knn_grid(pts, query, k, size)
    assert got is not None and got.shape == (m, k) and got.dtype == np.int64
    want = _brute(pts, query, k)
    d_got = ((pts[got] - query[:, None, :]) ** 2).sum(axis=2)
    d_want = ((pts[want] - query[:, None, :]) ** 2).sum(axis=2)
    np.testing.assert_array_equal(d_got, d_want)  # the same distances, nearest first
    np.testing.assert_array_equal(got, want)  # ties by row


def test_one_point_and_points_on_a_plane():
    one = np.array([[1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(knn_grid(one, one, 1, 0.1), [[0]])
    g = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0), [0.0]), -1).reshape(-1, 3) * 0.01
    got = knn_grid(g, g[:5], 9, 0.02)
    np.testing.assert_array_equal(got, _brute(g, g[:5], 9))


def test_a_grid_too_large_is_declined_and_bad_input_refused():
    far = np.array([[0.0, 0.0, 0.0], [1e5, 1e5, 1e5]])
    assert KnnGrid.build(far, 0.01) is None  # left to the k-d tree
    pts = np.zeros((3, 3))
    with pytest.raises(ValueError, match="finite"):
        KnnGrid.build(np.array([[0.0, np.nan, 0.0]]), 0.1)
    with pytest.raises(ValueError, match="cell size"):
        KnnGrid.build(pts, 0.0)
    grid = KnnGrid.build(pts, 0.1)
    assert grid is not None
    with pytest.raises(ValueError, match="k must lie"):
        grid.query(pts, 4)
    with pytest.raises(ValueError, match="finite"):
        grid.query(np.array([[np.inf, 0.0, 0.0]]), 1)


def test_k_equal_to_n_empty_query_and_queries_far_outside():
    rng = np.random.default_rng(2)
    pts = rng.uniform(0, 1, (40, 3))
    grid = KnnGrid.build(pts, 0.1)
    assert grid is not None
    np.testing.assert_array_equal(grid.query(pts, 40), _brute(pts, pts, 40))  # k = n
    assert grid.query(np.empty((0, 3)), 5).shape == (0, 5)
    far = np.array([[50.0, 0.5, 0.5], [-3.0, -3.0, 9.0], [0.5, 0.5, 0.5]])
    np.testing.assert_array_equal(grid.query(far, 7), _brute(pts, far, 7))


def test_two_python_threads_query_at_once():
    """The parallel kernel runs under the project's thread-safe layer (runtime.configure)."""
    from supportnode.kernels.knn import _PARALLEL_MIN_QUERIES

    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 1, (_PARALLEL_MIN_QUERIES, 3))  # enough queries for the threads
    grid = KnnGrid.build(pts, 0.05)
    assert grid is not None
    want = grid.query(pts, 12)
    with ThreadPoolExecutor(max_workers=2) as pool:
        got = list(pool.map(lambda _: grid.query(pts, 12), range(6)))
    for g in got:
        np.testing.assert_array_equal(g, want)


def test_warm_up_is_registered():
    assert _warm in runtime._WARMERS
    runtime.warm(["knn"])


def test_parallel_and_serial_searches_give_the_same_rows():
    from supportnode.kernels import knn

    rng = np.random.default_rng(7)
    pts = rng.uniform(0, 2, (knn._PARALLEL_MIN_QUERIES + 500, 3))
    grid = knn.KnnGrid.build(pts, 0.05)
    assert grid is not None
    parallel = grid.query(pts, 8)  # enough queries for the threads
    serial = knn._query_serial(np.ascontiguousarray(pts), 8, *grid._arrays())
    assert np.array_equal(parallel, serial)
    small = grid.query(pts[:100], 8)  # few: the serial twin
    assert np.array_equal(small, serial[:100])
    # Kept on the caller's thread on request, however many: the same rows.
    assert np.array_equal(grid.query(pts, 8, parallel=False), serial)
