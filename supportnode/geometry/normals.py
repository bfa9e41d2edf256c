"""Per-point normals from the covariance of the k nearest neighbours.

One exact k-nearest-neighbour search for all points: through a grid of cells in compiled code
(`supportnode.kernels.knn`, queries in cell order) for clouds of 1k points and more, else a
k-d tree (in the tree's leaf order, within a search radius estimated from a sample);
covariances summed over each point's neighbours in compiled code (chunked so memory stays
bounded), and the closed-form 3x3 eigen solver of :mod:`supportnode.geometry.linalg`. No
Python loop runs per point. Both searches give the same neighbours in the same order, so
the same normals bit for bit, except where distances tie exactly (quantised depth): the grid
orders ties by row and keeps the lowest rows at the k-th place, the k-d tree as it meets
them.

The report's optional normal filter (k=30, 160 s on 108k points there) is
:func:`filter_vertical_normals`, with the report's own suggested improvement: normals are
estimated only for the candidate surface points, while their neighbours are searched among all
points.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import numpy as np

from supportnode.errors import InputError
from supportnode.geometry.linalg import sym3_eigen_entries

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

    from supportnode.kernels.knn import KnnGrid

__all__ = ["estimate_normals", "filter_vertical_normals", "normals_at"]

# Neighbour indices per chunk: 600k is 20k points at k=30 (5 MB of indices): bounded memory,
# and the next chunk's search overlaps this one's covariances.
_CHUNK_VALUES = 600_000
# Queries below this are searched on one thread: a k-d tree query of 500 points (k = 10) took
# 0.65 ms on one thread and 0.88 ms on all (two) cores, which first have to be started.
_PARALLEL_MIN_QUERIES = 2048
# Clouds from which the exact search goes through a grid of cells (see _grid): measured
# faster than the k-d tree from 300 points up (1.5 vs 3.0 ms at 1000 points, k = 30).
_GRID_MIN_POINTS = 1024
# Queries from which a search radius is estimated first (see _knn_bound).
_BOUND_MIN_QUERIES = 16_384


def _as_points(points: np.ndarray, name: str = "points") -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"{name} must have shape (N, 3), got {pts.shape}")
    if pts.shape[0] < 3:
        raise InputError(f"{name}: need at least 3 points for normals, got {pts.shape[0]}")
    if not np.isfinite(pts).all():
        bad = int((~np.isfinite(pts).all(axis=1)).sum())
        raise InputError(f"{name}: {bad} of {pts.shape[0]} points are not finite (NaN/inf)")
    return pts


def normals_at(
    tree: cKDTree,
    points: np.ndarray,
    query: np.ndarray,
    k: int,
    workers: int = -1,
) -> tuple[np.ndarray, np.ndarray]:
    """Unoriented normals and curvature at ``query`` from neighbours among ``points``.

    from scipy.spatial import cKDTree  # here: ~0.18 s to import
    tree: ``cKDTree(points)``; points: (N, 3) float64 m; query: (M, 3) float64 m.
    workers: threads of the k-d tree query (-1: all cores).
    Returns ``(normals (M, 3) unit, sign arbitrary; curvature (M,) in [0, 1/3])``.
    """
    m = query.shape[0]
    n = points.shape[0]
    k = int(min(k, n))
    normals = np.empty((m, 3), dtype=np.float64)
    curvature = np.empty(m, dtype=np.float64)
    if m == 0:
        return normals, curvature
    chunk = max(1, _CHUNK_VALUES // k)
    if m < _PARALLEL_MIN_QUERIES:
        workers = 1  # the same neighbours; threads cost more to start than they save here
    neighbours = _chunk_search(tree, query, k, workers, chunk)
    if m <= chunk:
        # A query of one chunk has nothing to overlap: it is searched here, without a thread.
        _chunk_normals(_centred(points), neighbours(0), normals, curvature, 0)
        return normals, curvature
    # The query of the next chunk runs in a thread while this one's moments are summed (both
    # release the GIL): the single-threaded numpy work can then overlap the k-d tree search
    # instead of following it (when a core is free: 0-5% measured on a busy 2-core machine).
    with ThreadPoolExecutor(max_workers=1) as pool:
        pending = pool.submit(neighbours, 0)
        c = _centred(points)
        for start in range(0, m, chunk):  # loop over chunks of ~20k points, not over points
            stop = min(start + chunk, m)
            idx = pending.result()
            if stop < m:
                pending = pool.submit(neighbours, stop)
            _chunk_normals(c, idx, normals, curvature, start)
    return normals, curvature


def _chunk_search(
    tree: cKDTree, query: np.ndarray, k: int, workers: int, chunk: int
) -> Callable[[int], np.ndarray]:
    """The neighbour search of one chunk of ``chunk`` queries, by its first query's index."""
    bound = _knn_bound(tree, query, k, workers)

    def neighbours(start: int) -> np.ndarray:
        """(c, k) neighbour indices of the query chunk starting at ``start``: the exact k
        nearest, searched within ``bound`` first and without it where that found fewer."""
        q = query[start : start + chunk]
        if bound is None:
            return tree.query(q, k=k, workers=workers)[1].reshape(-1, k)
        dist, idx = tree.query(q, k=k, workers=workers, distance_upper_bound=bound)
        dist, idx = dist.reshape(-1, k), idx.reshape(-1, k)
        # All k found within the bound: every point beyond it is farther, so they are the k
        # nearest. Otherwise (sparse spots, ~5% of points) search again without the bound.
        short = np.flatnonzero(~np.isfinite(dist[:, -1]))
        if len(short):
            idx[short] = tree.query(q[short], k=k, workers=workers)[1].reshape(-1, k)
        return idx

    return neighbours


def _centred(points: np.ndarray) -> np.ndarray:
    """``points`` about the centre of their bounding box.

    So the cancellation in E[pp'] - E[p]E[p]' is about eps * R^2 with R the half-extent of the
    cloud: 2e-12 m^2 for R = 100 m against neighbourhood variances of 1e-5 m^2 and more (1e-7
    rad of normal), wherever the cloud lies. Column by column: numpy reduces (N, 3) arrays
    along axis 0 20x slower than 1-D."""
    origin = np.array([(points[:, j].min() + points[:, j].max()) / 2.0 for j in range(3)])
    return points - origin


def _chunk_normals(
    c: np.ndarray, idx: np.ndarray, normals: np.ndarray, curvature: np.ndarray, start: int
) -> None:
    """Write the normals and curvatures of the queries ``start:start + len(idx)`` in place.

    c: (N, 3) centred points; idx: (q, k) their neighbours. Each query's neighbourhood
    covariance is summed as its neighbours are read (compiled: no selection matrix, no
    gathers)."""
    # Imported here: importing the geometry (as the wire's types do) must not load numba.
    from supportnode.kernels.neighbourhoods import neighbourhood_covariances

    stop = start + len(idx)
    # The six entries as columns, xx, yy, zz, xy, xz, yz: no (rows, 3, 3) stack.
    evals, vec = sym3_eigen_entries(*neighbourhood_covariances(c, idx))
    evals = np.maximum(evals, 0.0)  # round-off can make the smallest slightly negative
    total = evals.sum(axis=1)
    safe = np.where(total > 0, total, 1.0)
    curvature[start:stop] = np.where(total > 0, evals[:, 0] / safe, 0.0)
    normals[start:stop] = vec


def _knn_bound(tree: cKDTree, query: np.ndarray, k: int, workers: int) -> float | None:
    """A search radius (m) within which most query points have their k nearest neighbours.

    The 95th percentile of the k-th neighbour distance over ~1000 evenly spread queries, plus
    10%. A k-d tree search that knows the radius prunes from the start instead of after its
    first k candidates: 18% less query time on 108k points at k = 30, for a 1% sample query.
    None for small queries (not worth the sample) or a degenerate radius.
    """
    if len(query) < _BOUND_MIN_QUERIES:
        return None
    dist, _ = tree.query(query[:: len(query) // 1024], k=k, workers=workers)
    bound = 1.1 * float(np.quantile(dist.reshape(-1, k)[:, -1], 0.95))
    return bound if np.isfinite(bound) and bound > 0 else None


def _grid(pts: np.ndarray, k: int) -> KnnGrid | None:
    """A grid for the exact k-nearest search of (N, 3) points (see `kernels.knn`), its cells
    0.7 of a typical k-th neighbour distance (measured best on sampled rooms and scans,
    against 0.5-1.4: most queries finish within two shells of cells around their own);
    None for small clouds (the k-d tree is as fast) or where the grid would be too large.

    The typical distance is the median k/8-th neighbour distance, among every 8th point, of
    ~500 evenly spread points: the same radius as the k-th among all, whatever the cloud's
    dimension (lines, surfaces, volumes), for a tree of an eighth of the points."""
    from supportnode.kernels.knn import KnnGrid

    if len(pts) < _GRID_MIN_POINTS or k > len(pts) // 8:
        return None
    sub = pts[::8]
    k_sub = max(2, -(-k // 8))
    from scipy.spatial import cKDTree  # here: ~0.18 s to import

    dist, _ = cKDTree(sub).query(pts[:: max(1, len(pts) // 512)], k=k_sub + 1)
    typical = float(np.median(dist[:, -1]))  # +1: a sampled point finds itself first
    if not (np.isfinite(typical) and typical > 0):
        return None
    return KnnGrid.build(pts, 0.7 * typical)


def normals_among(
    points: np.ndarray, query: np.ndarray, k: int, spacing: float, workers: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """`normals_at` of ``query`` (M, 3) among ``points`` (N, 3), float64 metres, on this
    thread: the neighbours come from a grid of cells ``spacing`` m wide (about twice a
    typical k-th neighbour distance is quickest), or from a k-d tree where that grid would not
    fit in memory, or for a big query with ``workers`` != 1 (its threads: the grid's parallel
    search compiles on its first use, seconds into a node's first scans after an install).
    Every search is exact: the same neighbours, the same normals."""
    from supportnode.kernels.knn import _PARALLEL_MIN_QUERIES, KnnGrid

    k = int(min(k, len(points)))
    big = workers != 1 and len(query) >= _PARALLEL_MIN_QUERIES
    grid = KnnGrid.build(points, spacing) if k >= 1 and spacing > 0 and not big else None
    if grid is None:
        from scipy.spatial import cKDTree  # here: ~0.18 s to import

        tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
        return normals_at(tree, points, query, k, workers)
    return _grid_normals(grid, query, k, parallel=False)


def _grid_normals(
    grid: KnnGrid, query: np.ndarray, k: int, parallel: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """`normals_at` with the neighbours from ``grid`` (the points' own), chunk by chunk
    (``parallel``: as `KnnGrid.query`)."""
    m = len(query)
    normals = np.empty((m, 3), dtype=np.float64)
    curvature = np.empty(m, dtype=np.float64)
    c = _centred(grid.points)
    chunk = max(1, _CHUNK_VALUES // k)
    for start in range(0, m, chunk):  # ~20k queries at a time: bounded memory
        idx = grid.query(query[start : start + chunk], k, parallel)
        _chunk_normals(c, idx, normals, curvature, start)
    return normals, curvature


def _grid_normals_any(grid: KnnGrid, query: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """`_grid_normals` for (M, 3) queries in any order: searched in cell order (neighbouring
    queries then read the same cells and moments), returned in theirs."""
    if query is grid.points:
        order = grid.sorted_index
    else:  # the queries' cells as the kernel finds them (clipped to the grid), in order
        cell = np.floor((query - grid.lo) / grid.size).astype(np.int64)
        cell = np.clip(cell, 0, grid.dims - 1)
        key = (cell[:, 0] * grid.dims[1] + cell[:, 1]) * grid.dims[2] + cell[:, 2]
        order = np.argsort(key, kind="stable")
    found, curv = _grid_normals(grid, np.take(query, order, axis=0), k)
    return _unsorted(order, found, curv)


def _unsorted(
    order: np.ndarray, found: np.ndarray, curv: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) normals and (M,) curvatures of the queries ``order`` back in input order."""
    # By a gather (np.take: 3-5x faster than fancy row indexing).
    rank = np.empty(len(order), dtype=np.intp)
    rank[order] = np.arange(len(order))  # query number of each input point
    return np.take(found, rank, axis=0), np.take(curv, rank)


def estimate_normals(
    points: np.ndarray,
    k: int = 30,
    viewpoint: np.ndarray | None = None,
    workers: int = -1,
) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals and surface variation ("curvature") of every point from its k neighbours.

    points: (N, 3) float64, metres, finite. k: neighbours including the point itself (clamped
    to N). viewpoint: (3,) metres; normals are flipped to face it (n . (viewpoint - p) >= 0),
    else to +z (n_z >= 0). workers: threads for the k-d tree query (-1: all cores).
    Returns ``(normals (N, 3) float64 unit, curvature (N,) float64)`` with curvature
    ``l0 / (l0 + l1 + l2)`` of the neighbourhood covariance eigenvalues (0 on a plane, 1/3 for
    isotropic scatter).
    """
    pts = _as_points(points)
    if k < 3:
        raise InputError(f"k must be at least 3 for a plane fit, got {k}")
    grid = _grid(pts, k)
    if grid is not None:
        normals, curvature = _grid_normals_any(grid, pts, k)
    else:
        from scipy.spatial import cKDTree  # here: ~0.18 s to import

        tree = cKDTree(pts, balanced_tree=False)  # sliding-midpoint build: 2x faster
        # Query in the tree's leaf order: neighbouring queries then touch the same nodes and
        # the same rows of the moments, which measured 10-25% faster than input order on
        # unordered clouds. (Sorting the points by a coarse tree first measured no faster.)
        order = tree.indices
        found, curv = normals_at(tree, pts, np.take(pts, order, axis=0), k, workers)
        normals, curvature = _unsorted(order, found, curv)
    if viewpoint is not None:
        vp = np.asarray(viewpoint, dtype=np.float64).reshape(3)
        flip = np.einsum("ij,ij->i", normals, vp - pts) < 0
    else:
        flip = normals[:, 2] < 0
    normals[flip] *= -1.0
    return normals, curvature


def filter_vertical_normals(
    points: np.ndarray,
    candidate_mask: np.ndarray,
    k: int = 30,
    max_tilt_deg: float = 20.0,
    workers: int = -1,
) -> np.ndarray:
    """The report's normal filter, applied only to candidate surface points.

    points: (N, 3) float64 metres, z up. candidate_mask: (N,) bool, the points that may lie on
    a support surface (e.g. points in flat, near-horizontal voxels); only these get a normal,
    but their neighbours are searched among all N points so a chair leg next to a seat still
    tilts the seat edge's normal as in the report. max_tilt_deg: largest angle between a
    normal and +z (either sign: a normal is an axis).
    Returns keep (N,) bool: candidates whose normal is within ``max_tilt_deg`` of vertical.
    """
    pts = _as_points(points)
    mask = np.asarray(candidate_mask, dtype=bool).reshape(-1)
    if mask.shape[0] != pts.shape[0]:
        raise InputError(f"candidate_mask has {mask.shape[0]} entries for {pts.shape[0]} points")
    keep = np.zeros(pts.shape[0], dtype=bool)
    if not mask.any():
        return keep
    k = min(k, len(pts))
    grid = _grid(pts, k)
    if grid is not None:
        sel = grid.sorted_index[mask[grid.sorted_index]]  # candidates in cell order
        normals, _ = _grid_normals(grid, pts[sel], k)
    else:
        from scipy.spatial import cKDTree  # here: ~0.18 s to import

        tree = cKDTree(pts, balanced_tree=False)
        sel = tree.indices[mask[tree.indices]]  # candidates in the tree's leaf order
        normals, _ = normals_at(tree, pts, pts[sel], k, workers=workers)
    keep[sel] = np.abs(normals[:, 2]) >= np.cos(np.radians(max_tilt_deg))
    return keep
