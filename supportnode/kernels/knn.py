"""Exact k nearest neighbours through a uniform grid of cells, in compiled code.

The normals of a cloud need every point's k nearest neighbours. A k-d tree query (scipy's,
on all cores) was three quarters of `estimate_normals` on 108k points at k = 30. Here the
points are sorted into cubic cells about as wide as a typical k-th neighbour distance, and
each query visits the shells of cells around its own (Chebyshev radius 0, 1, 2, ...) until
its k-th best distance lies within the radius the visited cells guarantee: the same
neighbours as any exact search. Cells are numbered z fastest, so a column of cells is one
run of sorted points, and a column farther than the k-th best found is skipped whole. Clouds
whose cell grid would not fit in memory are left to the k-d tree (`KnnGrid.build` returns None).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, parallel_chunksize, prange

from supportnode.kernels.runtime import configure, warmer

# Grids of more cells than this many per point (or than _MIN_CELLS) go to the k-d tree: a
# room at 2 cm cells is ~1e6 cells; a far lidar return would make it 1e12.
_CELLS_PER_POINT = 16
_MIN_CELLS = 1 << 22
# Queries from which the search runs on all the kernels' threads (the parallel kernel then
# compiles on its first use: ~7 s after an install, paid by big offline clouds only).
_PARALLEL_MIN_QUERIES = 16_384
_layer_chosen = False


@njit(cache=True, nogil=True)
def _bounds(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # Lowest and highest corner in one pass: numpy's min/max along axis 0 of an (N, 3) array
    # took 5.7 ms of a 9 ms build on 108k points.
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        lo[a] = hi[a] = pts[0, a]
    for p in range(1, pts.shape[0]):
        for a in range(3):
            lo[a] = min(lo[a], pts[p, a])
            hi[a] = max(hi[a], pts[p, a])
    return lo, hi


@njit(cache=True, nogil=True)
def _bin(
    pts: np.ndarray, lo: np.ndarray, inv: float, dims: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # Counting sort of the points by cell: the start of each cell's run (cells + 1,), and
    # the points' coordinates and indices in that order.
    n = pts.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    key = np.empty(n, np.int64)
    start = np.zeros(ncell + 1, np.int64)
    for p in range(n):
        i = min(int((pts[p, 0] - lo[0]) * inv), dims[0] - 1)
        j = min(int((pts[p, 1] - lo[1]) * inv), dims[1] - 1)
        k = min(int((pts[p, 2] - lo[2]) * inv), dims[2] - 1)
        key[p] = (i * dims[1] + j) * dims[2] + k
        start[key[p] + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    # Loops, not slice copies: numba compiles those for seconds on a fresh install.
    fill = np.empty(ncell, np.int64)
    for c in range(ncell):
        fill[c] = start[c]
    sorted_pts = np.empty((n, 3))
    sorted_idx = np.empty(n, np.int64)
    for p in range(n):
        at = fill[key[p]]
        fill[key[p]] += 1
        for a in range(3):
            sorted_pts[at, a] = pts[p, a]
        sorted_idx[at] = p
    return start, sorted_pts, sorted_idx


@njit(cache=True, nogil=True)
def _insert(bd: np.ndarray, bi: np.ndarray, m: int, k: int, d2: float, idx: int) -> int:
    # Insert (d2, idx) into the ascending lists bd, bi holding m entries (at most k): ties go
    # by index, so the result does not depend on the order cells are visited in.
    if m == k and (d2 > bd[k - 1] or (d2 == bd[k - 1] and idx > bi[k - 1])):
        return m
    pos = m if m < k else k - 1
    while pos > 0 and (bd[pos - 1] > d2 or (bd[pos - 1] == d2 and bi[pos - 1] > idx)):
        bd[pos] = bd[pos - 1]
        bi[pos] = bi[pos - 1]
        pos -= 1
    bd[pos] = d2
    bi[pos] = idx
    return min(m + 1, k)


@njit(cache=True, nogil=True)
def _slab(u: float, c: int) -> float:
    # Distance, in cells, from coordinate u (in cells) to the slab of cells [c, c + 1).
    return max(c - u, u - (c + 1), 0.0)


@njit(cache=True, nogil=True)
def _run(
    q: np.ndarray,
    k: int,
    sp: np.ndarray,
    si: np.ndarray,
    bd: np.ndarray,
    bi: np.ndarray,
    m: int,
    first: int,
    stop: int,
) -> int:
    # Offer the sorted points first..stop-1 (cells next to each other along z) to the lists.
    for p in range(first, stop):
        dx = sp[p, 0] - q[0]
        dy = sp[p, 1] - q[1]
        dz = sp[p, 2] - q[2]
        m = _insert(bd, bi, m, k, dx * dx + dy * dy + dz * dz, si[p])
    return m


@njit(cache=True, nogil=True)
def _query_one(
    q: np.ndarray,
    k: int,
    lo: np.ndarray,
    size: float,
    dims: np.ndarray,
    start: np.ndarray,
    sp: np.ndarray,
    si: np.ndarray,
    bd: np.ndarray,
    bi: np.ndarray,
) -> None:
    # q's cell as _bin computes a point's (clipped for queries outside the grid), and the
    # distance from q to that cell's nearest face, in cells.
    inv = 1.0 / size
    u0, u1, u2 = (q[0] - lo[0]) * inv, (q[1] - lo[1]) * inv, (q[2] - lo[2]) * inv
    c0 = min(max(int(np.floor(u0)), 0), dims[0] - 1)
    c1 = min(max(int(np.floor(u1)), 0), dims[1] - 1)
    c2 = min(max(int(np.floor(u2)), 0), dims[2] - 1)
    gap = min(max(u0 - c0, 0.0), max(c0 + 1 - u0, 0.0), max(u1 - c1, 0.0))
    gap = min(gap, max(c1 + 1 - u1, 0.0), max(u2 - c2, 0.0), max(c2 + 1 - u2, 0.0))
    shrink = size * size * (1.0 - 1e-9)  # cells^2 to m^2, less a hair for round-off
    nz = dims[2]
    m = 0
    r = 0
    while True:  # shells of cells at Chebyshev radius r around q's: 0, 1, 2, ...
        for i in range(max(c0 - r, 0), min(c0 + r, dims[0] - 1) + 1):
            li = _slab(u0, i)
            for j in range(max(c1 - r, 0), min(c1 + r, dims[1] - 1) + 1):
                lj = _slab(u1, j)
                if m == k and (li * li + lj * lj) * shrink > bd[k - 1]:
                    continue  # this column of cells is all farther than the k-th best
                base = (i * dims[1] + j) * nz
                if i == c0 - r or i == c0 + r or j == c1 - r or j == c1 + r:
                    # A column on the shell: its cells' points are one run in cell order.
                    z0, z1 = max(c2 - r, 0), min(c2 + r, nz - 1)
                    m = _run(q, k, sp, si, bd, bi, m, start[base + z0], start[base + z1 + 1])
                else:  # inside the shell: only its bottom and top cells are new
                    if c2 - r >= 0:
                        c = base + c2 - r
                        m = _run(q, k, sp, si, bd, bi, m, start[c], start[c + 1])
                    if c2 + r < nz:
                        c = base + c2 + r
                        m = _run(q, k, sp, si, bd, bi, m, start[c], start[c + 1])
        # Every point within (r + gap) cells of q lies in the cells visited.
        reach = r + gap
        if (m == k and bd[k - 1] <= reach * reach * shrink) or r >= max(dims[0], dims[1], nz):
            return
        r += 1


@njit(cache=True, nogil=True)
def _query_rows(query, k, lo, size, dims, start, sp, si, out, first, stop, bd, bi):
    # The k nearest of queries first..stop-1 into out's rows (bd, bi: scratch of k).
    for row in range(first, stop):
        _query_one(query[row], k, lo, size, dims, start, sp, si, bd, bi)
        for j in range(k):
            out[row, j] = bi[j]


@njit(cache=True, nogil=True, parallel=True)
def _query(
    query: np.ndarray,
    k: int,
    lo: np.ndarray,
    size: float,
    dims: np.ndarray,
    start: np.ndarray,
    sp: np.ndarray,
    si: np.ndarray,
) -> np.ndarray:
    m = query.shape[0]
    out = np.empty((m, k), np.int64)
    chunk = 256
    for b in prange((m + chunk - 1) // chunk):
        bd = np.empty(k)
        bi = np.empty(k, np.int64)
        _query_rows(query, k, lo, size, dims, start, sp, si, out, b * chunk,
                    min((b + 1) * chunk, m), bd, bi)  # fmt: skip
    return out


@njit(cache=True, nogil=True)
def _query_serial(
    query: np.ndarray,
    k: int,
    lo: np.ndarray,
    size: float,
    dims: np.ndarray,
    start: np.ndarray,
    sp: np.ndarray,
    si: np.ndarray,
) -> np.ndarray:
    # _query on one thread: the same rows. Its compilation takes ~1 s where the parallel
    # one's takes ~7 s, and small queries (the node's) gain nothing from threads.
    m = query.shape[0]
    out = np.empty((m, k), np.int64)
    _query_rows(query, k, lo, size, dims, start, sp, si, out, 0, m, np.empty(k),
                np.empty(k, np.int64))  # fmt: skip
    return out


@dataclass
class KnnGrid:
    """Points binned into cubic cells for exact k-nearest-neighbour queries (`build`)."""

    points: np.ndarray  # (N, 3) float64 m
    lo: np.ndarray  # (3,) lowest corner, m
    size: float  # cell edge, m
    dims: np.ndarray  # (3,) int64 cells along each axis
    start: np.ndarray  # (cells + 1,) int64 first sorted point of each cell
    sorted_points: np.ndarray  # (N, 3) float64, by cell
    sorted_index: np.ndarray  # (N,) int64 row in points of each sorted point

    @classmethod
    def build(cls, points: np.ndarray, size: float) -> KnnGrid | None:
        """The grid of ``points`` (N, 3) float m, finite, at cells of edge ``size`` m; None
        when it would hold too many cells (sparse, far-flung clouds: use a k-d tree).
        Raises ValueError for non-finite points or a size that is not positive and finite."""
        pts = np.ascontiguousarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
            raise ValueError(f"points must be (N, 3) with N >= 1, got {pts.shape}")
        if not (np.isfinite(size) and size > 0):
            raise ValueError(f"cell size must be positive and finite, got {size}")
        if not np.isfinite(pts).all():
            raise ValueError("points must be finite")
        lo, hi = _bounds(pts)
        extent = (hi - lo) / size
        if (extent >= 2.0**20).any():
            return None
        dims = extent.astype(np.int64) + 1
        cells = float(np.prod(dims.astype(np.float64)))
        if cells > max(_CELLS_PER_POINT * len(pts), _MIN_CELLS):
            return None
        start, sp, si = _bin(pts, lo, 1.0 / size, dims)
        return cls(pts, lo, float(size), dims, start, sp, si)

    def query(self, query: np.ndarray, k: int, parallel: bool = True) -> np.ndarray:
        """(M, k) int64 rows of the k nearest points of each of ``query`` (M, 3) float64 m,
        nearest first (equal distances by row); ``parallel`` False keeps a big query on this
        thread (the node's detection: no second core to take, no parallel kernel to compile
        on a first scan). Raises ValueError for k outside [1, N] or non-finite queries."""
        qry = np.ascontiguousarray(query, dtype=np.float64)
        if qry.ndim != 2 or qry.shape[1] != 3:
            raise ValueError(f"query must be (M, 3), got {qry.shape}")
        if not 1 <= k <= len(self.points):
            raise ValueError(f"k must lie in [1, {len(self.points)}], got {k}")
        if not np.isfinite(qry).all():
            raise ValueError("queries must be finite")
        if not parallel or len(qry) < _PARALLEL_MIN_QUERIES:
            return _query_serial(qry, int(k), *self._arrays())
        global _layer_chosen
        if not _layer_chosen:
            # A parallel kernel: its threading layer is the project's thread-safe choice
            # whoever calls first (a library user may never have warmed the kernels).
            configure()
            _layer_chosen = True
        # Blocks of 256 queries handed out 4 at a time, not in one half per thread: a thread
        # whose core is busy elsewhere then takes fewer (the queries' costs vary as well).
        with parallel_chunksize(4):
            return _query(qry, int(k), *self._arrays())

    def _arrays(self) -> tuple:
        return (self.lo, self.size, self.dims, self.start, self.sorted_points, self.sorted_index)


@warmer
def _warm() -> None:
    pts = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.3]])
    grid = KnnGrid.build(pts, 0.1)
    assert grid is not None
    grid.query(pts, 2)
