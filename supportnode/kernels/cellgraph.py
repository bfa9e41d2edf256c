"""A sparse grid of occupied cells: key lookup, window sums of moments, adjacent pairs.

The object segmentation works on fine cells (a few millimetres) of the points on no surface:
each cell's normal comes from the moments of the cells around it, and cells join along the
26-neighbourhood. Cells are given by their integer coordinates (F, 3), already offset so
that every coordinate lies in [pad, dim - pad); a cell's packed key is
``(i * dims[1] + j) * dims[2] + k``. An open-addressing table (Fibonacci hashing, linear
probing) maps keys to cell indices; each lookup is a few memory reads, where a sorted search
costs twenty.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.offsets import FORWARD_26
from supportnode.kernels.runtime import warmer
from supportnode.kernels.windows import _find, _home, _window_sums

MOMENTS = 10  # count, x, y, z, xx, yy, zz, xy, xz, yz


@njit(cache=True, nogil=True)
def _build(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    bits = 4
    while (1 << bits) < 2 * keys.size:
        bits += 1
    cap = 1 << bits
    shift = 64 - bits
    tk = np.full(cap, -1, np.int64)
    tv = np.empty(cap, np.int64)
    mask = cap - 1
    for i in range(keys.size):
        pos = _home(keys[i], shift)
        while tk[pos] != -1 and tk[pos] != keys[i]:
            pos = (pos + 1) & mask
        tk[pos] = keys[i]
        tv[pos] = i
    return tk, tv, shift


@njit(cache=True, nogil=True)
def _pairs(
    ijk: np.ndarray,
    dims: np.ndarray,
    tk: np.ndarray,
    tv: np.ndarray,
    shift: int,
    off: np.ndarray,
    centroid: np.ndarray,
    within: float,
) -> tuple[np.ndarray, np.ndarray]:
    n = ijk.shape[0]
    src = np.empty(n * off.shape[0], np.int64)
    dst = np.empty(n * off.shape[0], np.int64)
    check = within < np.inf
    e = 0
    for c in range(n):
        for o in range(off.shape[0]):
            key = ((ijk[c, 0] + off[o, 0]) * dims[1] + ijk[c, 1] + off[o, 1]) * dims[2] + (
                ijk[c, 2] + off[o, 2]
            )
            j = _find(tk, tv, shift, key)
            if j < 0:
                continue
            if check:
                # As numpy's norm of the difference: squares summed left to right, then sqrt.
                dx = centroid[c, 0] - centroid[j, 0]
                dy = centroid[c, 1] - centroid[j, 1]
                dz = centroid[c, 2] - centroid[j, 2]
                if not np.sqrt(dx * dx + dy * dy + dz * dz) <= within:
                    continue
            src[e] = c
            dst[e] = j
            e += 1
    return src[:e], dst[:e]


@njit(cache=True, nogil=True)
def _extent(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    finite = True
    for p in range(pts.shape[0]):
        for a in range(3):
            v = pts[p, a]
            if not np.isfinite(v):
                finite = False
            lo[a] = min(lo[a], v)
            hi[a] = max(hi[a], v)
    return lo, hi, finite


@njit(cache=True, nogil=True)
def _bin_points(
    pts: np.ndarray, base: np.ndarray, size: float, pad: int, dims: np.ndarray, bits: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    cap = 1 << bits
    shift = 64 - bits
    mask = cap - 1
    tk = np.full(cap, -1, np.int64)
    tv = np.empty(cap, np.int64)
    m = pts.shape[0]
    of_point = np.empty(m, np.int64)
    cells = np.empty((m, 3), np.int64)
    mom = np.zeros((m, MOMENTS))
    n = 0
    for p in range(m):
        # The same float operations as (pts - base) / size, floored, in numpy.
        x, y, z = pts[p, 0] - base[0], pts[p, 1] - base[1], pts[p, 2] - base[2]
        i = int(np.floor(x / size)) + pad
        j = int(np.floor(y / size)) + pad
        k = int(np.floor(z / size)) + pad
        key = (i * dims[1] + j) * dims[2] + k
        pos = _home(key, shift)
        while tk[pos] != -1 and tk[pos] != key:
            pos = (pos + 1) & mask
        if tk[pos] == -1:
            tk[pos] = key
            tv[pos] = n
            cells[n, 0], cells[n, 1], cells[n, 2] = i, j, k
            n += 1
        c = tv[pos]
        of_point[p] = c
        mom[c, 0] += 1.0
        mom[c, 1] += x
        mom[c, 2] += y
        mom[c, 3] += z
        mom[c, 4] += x * x
        mom[c, 5] += y * y
        mom[c, 6] += z * z
        mom[c, 7] += x * y
        mom[c, 8] += x * z
        mom[c, 9] += y * z
    return cells[:n].copy(), of_point, mom[:n].copy(), tk, tv


def bin_points(
    points: np.ndarray, size: float, pad: int
) -> tuple[CellGrid, np.ndarray, np.ndarray, np.ndarray]:
    """The occupied ``size`` cells of points (M, 3) float64, metres, in one pass after their
    extent: the grid (cells counted from the points' least corner ``base`` (3,), padded by
    ``pad`` cells), each point's cell (M,), each cell's moments (F, 10) (count, x, y, z, xx,
    yy, zz, xy, xz, yz of the points relative to ``base``), and ``base``. Cells are numbered
    in the order their first point comes."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if not size > 0:
        raise ValueError(f"cell size must be > 0, got {size}")
    lo, hi, finite = _extent(pts)
    if not finite:
        raise ValueError("points must be finite")
    if len(pts) == 0:
        lo = hi = np.zeros(3)
    top = np.floor((hi - lo) / size).astype(np.int64) + pad
    dims = top + pad + 1
    if float(np.prod(dims.astype(np.float64))) >= 2.0**62:
        raise ValueError(f"grid of {dims.tolist()} cells is too large to pack")
    bits = 4
    while (1 << bits) < 2 * max(len(pts), 1):
        bits += 1
    cells, of_point, mom, tk, tv = _bin_points(pts, lo, float(size), int(pad), dims, bits)
    return CellGrid.from_table(cells, dims, pad, tk, tv, 64 - bits), of_point, mom, lo


class CellGrid:
    """The occupied cells (F, 3) int64 coordinates of a sparse grid with its lookup table.

    ijk: cell coordinates, every one at least ``pad`` from 0 and from ``dims`` on each axis
    (windows and offsets of up to ``pad`` cells stay inside the packing), pairwise distinct.
    """

    def __init__(self, ijk: np.ndarray, dims: np.ndarray, pad: int) -> None:
        ijk = np.ascontiguousarray(ijk, dtype=np.int64).reshape(-1, 3)
        dims = np.ascontiguousarray(dims, dtype=np.int64).reshape(3)
        if len(ijk) and ((ijk < pad).any() or (ijk >= dims - pad).any()):
            raise ValueError(f"cell coordinates must lie at least {pad} cells inside the grid")
        if int(np.prod(dims.astype(np.float64))) >= 2**62:
            raise ValueError(f"grid of {dims.tolist()} cells is too large to pack")
        self.ijk, self.dims, self.pad = ijk, dims, int(pad)
        keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
        self._tk, self._tv, self._shift = _build(keys)

    @classmethod
    def from_table(
        cls, ijk: np.ndarray, dims: np.ndarray, pad: int, tk: np.ndarray, tv: np.ndarray, shift: int
    ) -> CellGrid:
        """A grid whose lookup table was built with its cells (see :func:`bin_points`)."""
        grid = cls.__new__(cls)
        grid.ijk, grid.dims, grid.pad = ijk, np.asarray(dims, np.int64), int(pad)
        grid._tk, grid._tv, grid._shift = tk, tv, int(shift)
        return grid

    def window_sums(
        self,
        mom: np.ndarray,
        w: int,
        label: np.ndarray | None = None,
        at: np.ndarray | None = None,
    ) -> np.ndarray:
        """(F, M) sums of ``mom`` (F, M) float64 over the cells within ``w`` cells of each
        cell (Chebyshev), only those of the cell's own ``label`` (F,) when given; (K, M) for
        the cells ``at`` (K,) only when given."""
        if not 0 <= w <= self.pad:
            raise ValueError(f"window {w} exceeds the grid's padding {self.pad}")
        mom = np.ascontiguousarray(mom, dtype=np.float64)
        if mom.ndim != 2 or len(mom) != len(self.ijk):
            raise ValueError("moments must be (F, M), a row per cell")
        lab = np.zeros(len(self.ijk), np.int64) if label is None else np.asarray(label, np.int64)
        if lab.shape != (len(self.ijk),):
            raise ValueError("labels must be (F,), one per cell")
        rows = np.arange(len(self.ijk)) if at is None else np.asarray(at, np.int64).ravel()
        if len(rows) and (rows.min() < 0 or rows.max() >= len(self.ijk)):
            raise ValueError("cells asked for lie outside the grid")
        same = label is not None
        return _window_sums(self.ijk, self.dims, mom, int(w), lab, same, rows)

    def adjacent_pairs(
        self, centroid: np.ndarray | None = None, within: float = np.inf
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pairs (src, dst) of 26-adjacent cells, each pair once: two (E,) int64; with
        ``centroid`` (F, 3) float64, only those whose centroids lie within ``within`` (same
        unit) of each other."""
        if self.pad < 1:
            raise ValueError("adjacent pairs need a padding of at least one cell")
        if centroid is None:
            centroid, within = np.zeros((len(self.ijk), 3)), np.inf
        centroid = np.ascontiguousarray(centroid, dtype=np.float64)
        if centroid.shape != (len(self.ijk), 3):
            raise ValueError("centroids must be (F, 3), a row per cell")
        grid = (self.ijk, self.dims, self._tk, self._tv, self._shift)
        return _pairs(*grid, FORWARD_26, centroid, float(within))


@warmer
def _warm() -> None:
    g = CellGrid(np.array([[2, 2, 2], [2, 3, 2]]), np.array([5, 6, 5]), 2)
    g.window_sums(np.ones((2, MOMENTS)), 1)
    g.window_sums(np.ones((2, MOMENTS)), 1, np.array([0, 1]), np.array([1]))
    g.adjacent_pairs()
    g.adjacent_pairs(np.zeros((2, 3)), 1.0)
    bin_points(np.array([[0.0, 0, 0], [0.001, 0, 0]]), 0.01, 1)
    bin_points(np.zeros((0, 3)), 0.01, 1)
