"""Support look-up: the surface under each point from the stacked footprint rasters of
`geometry.objects.support_lookup._SupportTable`, in one compiled pass over the points (the
numpy version made eight (M,) temporaries); and each cluster's bottom and lowest points,
what its support is decided on. Releases the interpreter lock."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["cluster_bottoms", "level_split", "lowest_per_cell", "table_lookup"]


@njit(cache=True, nogil=True)
def _lookup(cp, threshold, cell, origin, best):
    m = cp.shape[0]
    _, h, w = best.shape
    out = np.empty(m, np.int64)
    for p in range(m):
        z = cp[p, 2]
        k = 0  # np.searchsorted(threshold, z, side="right"): thresholds <= z
        while k < threshold.size and threshold[k] <= z:
            k += 1
        i = np.int64(math.floor(cp[p, 0] / cell[0])) - origin[0]
        j = np.int64(math.floor(cp[p, 1] / cell[1])) - origin[1]
        if 0 <= i < h and 0 <= j < w:
            out[p] = best[k, i, j]
        else:
            out[p] = -1
    return out


def table_lookup(
    cp: np.ndarray, threshold: np.ndarray, cell: np.ndarray, origin: np.ndarray, best: np.ndarray
) -> np.ndarray:
    """(M,) int64 surface id under each point of cp (M, 3) float64 (finite, m), -1 for none:
    ``best[k, i, j]`` with k the number of ``threshold`` (S,) ascending heights at or below
    the point's z and (i, j) its cell ``floor(xy / cell) - origin`` on the (S + 1, H, W)
    int32 raster ``best``; outside the raster, -1."""
    best = np.ascontiguousarray(best, np.int32)
    threshold = np.ascontiguousarray(threshold, np.float64)
    if best.ndim != 3 or best.shape[0] != threshold.size + 1:
        raise ValueError(f"best must be (S + 1, H, W) for {threshold.size} thresholds")
    if threshold.size > 1 and np.any(np.diff(threshold) < 0):
        raise ValueError("thresholds must ascend")
    cell = np.ascontiguousarray(cell, np.float64).reshape(2)
    origin = np.ascontiguousarray(origin, np.int64).reshape(2)
    return _lookup(np.ascontiguousarray(cp, np.float64), threshold, cell, origin, best)


@njit(cache=True, nogil=True)
def _lowest(cp, cell, origin, h, w):
    low = np.full((h, w), np.inf)
    for p in range(cp.shape[0]):
        i = np.int64(math.floor(cp[p, 0] / cell[0])) - origin[0]
        j = np.int64(math.floor(cp[p, 1] / cell[1])) - origin[1]
        if 0 <= i < h and 0 <= j < w and cp[p, 2] < low[i, j]:
            low[i, j] = cp[p, 2]
    return low


def lowest_per_cell(
    cp: np.ndarray, cell: np.ndarray, origin: np.ndarray, shape: tuple[int, int]
) -> np.ndarray:
    """(H, W) float64 lowest z (m) of the points of cp (M, 3) float64 (finite, m) in each cell
    ``floor(xy / cell) - origin`` of an H x W raster (``shape``); inf where none lies. One
    pass, where ``np.minimum.at`` took ~5 ms on the 400k candidates of a merged lidar map."""
    h, w = (int(v) for v in shape)
    if h < 0 or w < 0:
        raise ValueError(f"shape must not be negative, got {shape}")
    cell = np.ascontiguousarray(cell, np.float64).reshape(2)
    origin = np.ascontiguousarray(origin, np.int64).reshape(2)
    return _lowest(np.ascontiguousarray(cp, np.float64).reshape(-1, 3), cell, origin, h, w)


@njit(cache=True, nogil=True)
def _level_split(cp, rows, support, planes, level, reach):
    m = cp.shape[0]
    kept = np.empty(m, np.int64)
    kept_cp = np.empty((m, 3))
    kept_support = np.empty(m, np.int64)
    low = np.empty(m, np.int64)
    at = np.empty(m, np.int64)
    i = 0
    j = 0
    b = 0
    for p in range(m):
        s = support[p]
        h = np.nan
        if 0 <= s < planes.shape[0]:
            cx, cy, cz, gx, gy = (
                planes[s, 0],
                planes[s, 1],
                planes[s, 2],
                planes[s, 3],
                planes[s, 4],
            )
            h = cp[p, 2] - (cz + gx * (cp[p, 0] - cx) + gy * (cp[p, 1] - cy))
        if abs(h) <= level:  # False for NaN
            at[j] = p
            j += 1
            continue
        kept[i] = rows[p]
        for a in range(3):
            kept_cp[i, a] = cp[p, a]
        kept_support[i] = s
        if h <= level + reach:
            low[b] = i
            b += 1
        i += 1
    return kept, kept_cp, kept_support, low, at, i, b, j


def level_split(
    cp: np.ndarray,
    rows: np.ndarray,
    support: np.ndarray,
    planes: np.ndarray,
    level: float,
    reach: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The points cp (M, 3) float64 (rows (M,) int64 their ids, support (M,) int64 their
    surfaces, planes (S, 5) = (cx, cy, cz, gx, gy) their planes z = cz + gx (x - cx) + gy (y - cy), NaN rows for none) parted at their surface's level: those
    more than ``level`` m off its plane (or over none) are kept, in order. Returns the kept
    points' rows (K,), points (K, 3), supports (K,), the positions (B,) among them of those
    within level + reach above their plane (an object's bottom), and the positions (M - K,)
    int64 of the others in cp. One compiled pass where numpy took four boolean masks and
    three gathers."""
    cp = np.ascontiguousarray(cp, np.float64).reshape(-1, 3)
    rows = np.ascontiguousarray(rows, np.int64).reshape(-1)
    support = np.ascontiguousarray(support, np.int64).reshape(-1)
    if not len(rows) == len(support) == len(cp):
        raise ValueError(f"rows ({len(rows)}), support ({len(support)}) and cp ({len(cp)}) differ")
    planes = np.ascontiguousarray(planes, np.float64).reshape(-1, 5)
    kept, kept_cp, kept_support, low, at, k, b, n = _level_split(
        cp, rows, support, planes, float(level), float(reach)
    )
    return kept[:k], kept_cp[:k], kept_support[:k], low[:b], at[:n]


@njit(cache=True, nogil=True)
def _select(buf, n, k):
    """Rearrange buf[:n] so that buf[k] is its k-th smallest, those before it no larger and
    those after no smaller (quickselect, Hoare's partition, median-of-three pivots)."""
    lo, hi = 0, n - 1
    while lo < hi:
        mid = (lo + hi) // 2
        a, b, c = buf[lo], buf[mid], buf[hi]
        pivot = max(min(a, b), min(max(a, b), c))
        i, j = lo, hi
        while i <= j:
            while buf[i] < pivot:
                i += 1
            while buf[j] > pivot:
                j -= 1
            if i <= j:
                buf[i], buf[j] = buf[j], buf[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return buf[k]


@njit(cache=True, nogil=True)
def _low_percentile(z, a, b, q, buf):
    """numpy's linear percentile q (%) of z[a:b]: the two order statistics it interpolates,
    selected in a copy (buf: scratch of at least b - a values)."""
    n = b - a
    for r in range(n):
        buf[r] = z[a + r]
    v = (n - 1) * (q / 100)
    i = int(v)
    lo = _select(buf, n, i)
    hi = buf[i + 1]  # the next order statistic: the smallest of those after the i-th
    for r in range(i + 2, n):
        hi = min(hi, buf[r])
    t = v - i
    d = hi - lo
    return hi - d * (1 - t) if t >= 0.5 else lo + d * t  # numpy's _lerp


@njit(cache=True, nogil=True)
def _bottoms(z, runs, band, min_points, q):
    c = runs.shape[0]
    bottom = np.empty(c)
    n_low = np.zeros(c, np.int64)
    longest = 0
    total = 0
    for k in range(c):
        longest = max(longest, runs[k, 1] - runs[k, 0])
        total += runs[k, 1] - runs[k, 0]
    buf = np.empty(longest)
    low = np.empty(total, np.int64)
    m = 0
    for k in range(c):
        a, b = runs[k, 0], runs[k, 1]
        if b - a >= min_points:
            bottom[k] = _low_percentile(z, a, b, q, buf)
        else:
            lowest = z[a]
            for r in range(a + 1, b):
                lowest = min(lowest, z[r])
            bottom[k] = lowest
        top = bottom[k] + band
        for r in range(a, b):
            if z[r] <= top:
                low[m] = r
                m += 1
                n_low[k] += 1
    rows = np.empty(m, np.int64)
    for i in range(m):  # a loop, not a slice copy: that compiles for seconds
        rows[i] = low[i]
    return bottom, n_low, rows


def cluster_bottoms(
    z: np.ndarray, runs: np.ndarray, band: float, min_points: int = 100, q: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each cluster's bottom and lowest points. z (P,) float64 heights (m) of the clusters'
    points, cluster k holding rows ``runs[k, 0] : runs[k, 1]`` (runs (C, 2) int64). A cluster's bottom is the percentile q (numpy's linear method) of its
    heights when it has ``min_points`` or more, else its lowest height; its low points are
    those at most ``band`` m above it. Returns bottom (C,), the low points' count (C,) and
    their rows (L,) int64, cluster by cluster (in the order of ``runs``), in row order."""
    z = np.ascontiguousarray(z, np.float64)
    runs = np.ascontiguousarray(runs, np.int64).reshape(-1, 2)
    if len(runs) and (np.any(runs[:, 1] <= runs[:, 0]) or runs.min() < 0 or runs.max() > len(z)):
        raise ValueError(f"runs must be non-empty row ranges [a, b) of z's {len(z)} rows")
    if not 0 <= q < 50:
        raise ValueError(f"q must be a low percentile in [0, 50), got {q}")
    return _bottoms(z, runs, float(band), int(min_points), float(q))


@njit(cache=True, nogil=True)
def _level_points(cp, planes, level):
    # A loop, not np.flatnonzero: numba's version lives in numba.np.arraymath, which a cache
    # load then imports, and with it scipy's BLAS (~80 ms of a fresh `supportnode detect`).
    live = np.empty(planes.shape[0], np.int64)
    k = 0
    for s in range(planes.shape[0]):
        if np.isfinite(planes[s, 0]):
            live[k] = s
            k += 1
    live = live[:k]
    pl = planes[live]
    m = cp.shape[0]
    count = np.zeros(m, np.int8)  # planes at whose level each point lies (first pass)
    for p in range(m):
        x, y, z = cp[p, 0], cp[p, 1], cp[p, 2]
        for s in range(k):
            h = z - (pl[s, 2] + pl[s, 3] * (x - pl[s, 0]) + pl[s, 4] * (y - pl[s, 1]))
            if abs(h) <= level:
                count[p] += 1
    n = 0
    for p in range(m):
        n += count[p]
    rows = np.empty(n, np.int64)
    surf = np.empty(n, np.int64)
    i = 0
    for p in range(m):
        if count[p] == 0:
            continue
        x, y, z = cp[p, 0], cp[p, 1], cp[p, 2]
        for s in range(k):
            h = z - (pl[s, 2] + pl[s, 3] * (x - pl[s, 0]) + pl[s, 4] * (y - pl[s, 1]))
            if abs(h) <= level:
                rows[i] = p
                surf[i] = live[s]
                i += 1
    return rows, surf


def level_points(cp: np.ndarray, planes: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """The points of cp (M, 3) float64 metres within ``level`` m of a plane of planes (S, 5)
    = (cx, cy, cz, gx, gy), z = cz + gx (x - cx) + gy (y - cy) (NaN rows: none): their rows
    (K,) int64 ascending and each one's plane (K,) int64 (a point at two planes' levels
    twice). One compiled pass over the points for all planes."""
    cp = np.ascontiguousarray(cp, np.float64).reshape(-1, 3)
    planes = np.ascontiguousarray(planes, np.float64).reshape(-1, 5)
    return _level_points(cp, planes, float(level))


@warmer
def _warm() -> None:
    cluster_bottoms(np.linspace(0.0, 1.0, 150), np.array([[0, 120], [120, 150]]), 0.02)
    best = np.full((2, 2, 2), -1, np.int32)
    best[1, 0, 0] = 0
    cp = np.array([[0.01, 0.01, 0.5], [0.5, 0.5, 0.0]])
    table_lookup(cp, np.array([0.2]), np.array([0.1, 0.1]), np.zeros(2, np.int64), best)
    lowest_per_cell(cp, np.array([0.1, 0.1]), np.zeros(2, np.int64), (2, 2))
    level_split(cp, np.arange(2), np.array([0, -1]), np.zeros((1, 5)), 0.003, 0.03)
    level_points(cp, np.zeros((1, 5)), 0.003)
