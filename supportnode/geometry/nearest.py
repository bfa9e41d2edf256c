"""Nearest points and neighbour counts for the detection's queries, without a k-d tree.

The detection asks small questions many times (which point of a part lies nearest, how many
points lie around a face's points, how far apart a cloud's points lie). These answer them
exactly through compiled cells (`kernels.knn`, `kernels.radius`): the same distances and
counts as scipy's cKDTree, equal distances going to the lowest row. Importing scipy.spatial
for them cost a ``supportnode detect`` process ~0.18 s, a quarter of its run.

Points and queries: (N, 2) or (N, 3) float64 metres, finite; both of one width.
"""

from __future__ import annotations

import numpy as np

from supportnode.kernels.radius import as_xyz, count_within, nearest_within

__all__ = ["count_within", "nearest", "nearest_within", "neighbour_distances", "within"]

_MAX_CELLS_PER_AXIS = float(1 << 19)  # KnnGrid takes up to 2**20


def nearest(points: np.ndarray, query: np.ndarray) -> np.ndarray:
    """(Q,) int64: the row of the point of ``points`` (N >= 1) nearest each of ``query``."""
    return _knn_rows(points, query, 1)[:, 0]


def neighbour_distances(points: np.ndarray, query: np.ndarray, k: int) -> np.ndarray:
    """(Q, k) float64 m: the distances to the k nearest of ``points`` (N >= k) from each of
    ``query``, nearest first (a query among the points finds itself first, at 0)."""
    pts, qry = as_xyz(points), as_xyz(query, "query")
    rows = _knn_rows(pts, qry, k)
    d = pts[rows] - qry[:, None, :]
    return np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])


def within(points: np.ndarray, query: np.ndarray, bound: float) -> np.ndarray:
    """(Q,) bool: whether a point of ``points`` lies closer than ``bound`` m to each query."""
    return nearest_within(points, query, bound)[1] >= 0


def _knn_rows(points: np.ndarray, query: np.ndarray, k: int) -> np.ndarray:
    from supportnode.kernels.knn import KnnGrid

    pts, qry = as_xyz(points), as_xyz(query, "query")
    if not 1 <= k <= len(pts):
        raise ValueError(f"k must lie in [1, {len(pts)}] (the points), got {k}")
    if len(qry) == 0:
        return np.zeros((0, k), np.int64)
    grid = KnnGrid.build(pts, _cell(pts))
    # _cell's edge makes at most 8 cells a point, within 2**19 along an axis: KnnGrid's
    # limits are 16 a point and 2**20.
    assert grid is not None
    # One thread: these queries are small, and the parallel kernel would compile for ~7 s
    # on a fresh install's first big cloud.
    return grid.query(qry, k, parallel=False)


def _cell(pts: np.ndarray) -> float:
    """A cell edge (m) giving about one point a cell over the axes the points spread along."""
    extent = pts.max(axis=0) - pts.min(axis=0)
    spread = extent > 0
    while spread.any():
        size = float(np.prod(extent[spread]) / len(pts)) ** (1.0 / int(spread.sum()))
        thin = spread & (extent < size)  # an axis thinner than a cell is no axis to fill
        if not thin.any():
            return max(size, float(extent.max()) / _MAX_CELLS_PER_AXIS)
        spread &= ~thin
    return 1.0
