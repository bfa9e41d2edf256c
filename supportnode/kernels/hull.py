"""Convex hulls of the x, y footprints of many clusters in one compiled pass.

Qhull costs ~0.1 ms a call before it starts, and a map has some 50 clusters a detection; its
input first had to be thinned (the ends of vertical lines, an even sample of dense clusters).
Here each cluster's points are filtered by the octagon of its extreme points (Akl-Toussaint:
a point strictly inside a polygon of hull points is no hull vertex), the rest sorted and
chained (Andrew's monotone chain): the exact hull of all the points, in one call for all.

Rings are counter-clockwise, without collinear vertices, starting at the lowest x (then y);
a cluster whose points are all on a line gives its two ends (lowest first), one point gives
itself: as Qhull with its degenerate cases handled, on points in general position.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["footprint_hulls"]

# Clusters with more points than this outside their octagon are thinned by the hull of an
# even sample of about _SAMPLE of them first.
_SAMPLE_ABOVE = 4096
_SAMPLE = 1024
# Relative round-off below which three points are on one line (see _turns_left).
_COLLINEAR = 1e-12


@njit(cache=True, nogil=True)
def _cross(ox: float, oy: float, ax: float, ay: float, bx: float, by: float) -> float:
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


@njit(cache=True, nogil=True)
def _turns_left(ox: float, oy: float, ax: float, ay: float, bx: float, by: float) -> bool:
    # o -> a -> b turns left by more than round-off: points on one line up to the last bits
    # of their coordinates (decimal data: 0.013, 0.104, 1.105) are collinear, as for Qhull.
    ux, uy, vx, vy = ax - ox, ay - oy, bx - ox, by - oy
    return ux * vy - uy * vx > _COLLINEAR * (abs(ux) + abs(uy)) * (abs(vx) + abs(vy))


@njit(cache=True, nogil=True)
def _extremes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # The first point extreme along each of eight directions, counter-clockwise from -x (-x,
    # -x-y, -y, x-y, x, x+y, y, y-x), in one pass with the maxima in registers.
    e0 = e1 = e2 = e3 = e4 = e5 = e6 = e7 = 0
    b0 = b1 = b2 = b3 = b4 = b5 = b6 = b7 = -np.inf
    for i in range(len(x)):
        xi, yi = x[i], y[i]
        s, t = xi + yi, xi - yi
        if -xi > b0:
            b0, e0 = -xi, i
        if -s > b1:
            b1, e1 = -s, i
        if -yi > b2:
            b2, e2 = -yi, i
        if t > b3:
            b3, e3 = t, i
        if xi > b4:
            b4, e4 = xi, i
        if s > b5:
            b5, e5 = s, i
        if yi > b6:
            b6, e6 = yi, i
        if -t > b7:
            b7, e7 = -t, i
    out = np.empty(8, np.int64)
    out[0], out[1], out[2], out[3] = e0, e1, e2, e3
    out[4], out[5], out[6], out[7] = e4, e5, e6, e7
    return out


@njit(cache=True, nogil=True)
def _survivors(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # Indices of the points not strictly inside the octagon of the extreme points along eight
    # directions (see _extremes: counter-clockwise, so the octagon's vertices are in that order).
    n = len(x)
    ex = _extremes(x, y)
    # The octagon's edges once (a repeated vertex makes none), not per point.
    edge = np.empty((8, 4))
    edges = 0
    for d in range(8):
        a, b = ex[d], ex[(d + 1) % 8]
        if x[a] == x[b] and y[a] == y[b]:
            continue
        edge[edges, 0], edge[edges, 1] = x[a], y[a]
        edge[edges, 2], edge[edges, 3] = x[b], y[b]
        edges += 1
    keep = np.empty(n, np.int64)
    m = 0
    if edges < 3:
        for i in range(n):
            keep[i] = i
        return keep
    for i in range(n):
        inside = True
        for d in range(edges):
            if _cross(edge[d, 0], edge[d, 1], edge[d, 2], edge[d, 3], x[i], y[i]) <= 0.0:
                inside = False
                break
        if not inside:
            keep[m] = i
            m += 1
    return keep[:m]


@njit(cache=True, nogil=True)
def _chain(x: np.ndarray, y: np.ndarray, idx: np.ndarray, ring: np.ndarray) -> int:
    # Andrew's monotone chain over the points idx (sorted by x, then y); writes the ring's
    # point indices into ring (room for 2 * len(idx) + 1), returns its length.
    k = 0
    for t in range(len(idx)):  # lower chain, left to right
        i = idx[t]
        while k >= 2 and not _turns_left(
            x[ring[k - 2]], y[ring[k - 2]], x[ring[k - 1]], y[ring[k - 1]], x[i], y[i]
        ):
            k -= 1
        ring[k] = i
        k += 1
    low = k + 1
    for t in range(len(idx) - 2, -1, -1):  # upper chain, right to left
        i = idx[t]
        while k >= low and not _turns_left(
            x[ring[k - 2]], y[ring[k - 2]], x[ring[k - 1]], y[ring[k - 1]], x[i], y[i]
        ):
            k -= 1
        ring[k] = i
        k += 1
    k -= 1  # the last point is the first again
    if k == 2 and x[ring[0]] == x[ring[1]] and y[ring[0]] == y[ring[1]]:
        k = 1  # every point the same
    return max(k, 1)


@njit(cache=True, nogil=True)
def _before(x: np.ndarray, y: np.ndarray, i: int, j: int) -> bool:
    return x[i] < x[j] or (x[i] == x[j] and y[i] < y[j])


@njit(cache=True, nogil=True)
def _sort_xy(idx: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # Bottom-up merge sort of idx by x, then y; returns the sorted copy. Hand-written: numba's
    # generic sorts cost seconds of compiling on a fresh install, this a fraction.
    n = len(idx)
    src = idx.copy()
    dst = np.empty(n, np.int64)
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid = min(lo + width, n)
            hi = min(lo + 2 * width, n)
            i, j, k = lo, mid, lo
            while i < mid and j < hi:
                if _before(x, y, src[j], src[i]):
                    dst[k] = src[j]
                    j += 1
                else:
                    dst[k] = src[i]
                    i += 1
                k += 1
            while i < mid:
                dst[k] = src[i]
                i += 1
                k += 1
            while j < hi:
                dst[k] = src[j]
                j += 1
                k += 1
        src, dst = dst, src
        width *= 2
    return src


@njit(cache=True, nogil=True)
def _sorted_hull(x: np.ndarray, y: np.ndarray, cand: np.ndarray) -> np.ndarray:
    # The ring (point indices) of the points cand, chained in x, then y order.
    order = _sort_xy(cand, x, y)
    ring = np.empty(2 * len(order) + 1, np.int64)
    return ring[: _chain(x, y, order, ring)]


@njit(cache=True, nogil=True)
def _last_at_most(xs: np.ndarray, v: float, descending: bool) -> int:
    # The last index whose xs (ascending, or descending) is <= v (> v when descending).
    lo, hi = 0, len(xs) - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if (xs[mid] > v) if descending else (xs[mid] <= v):
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(cache=True, nogil=True)
def _outside(x: np.ndarray, y: np.ndarray, cand: np.ndarray, ring: np.ndarray) -> np.ndarray:
    # The points of cand not strictly inside the convex ring (counter-clockwise from the
    # lowest x, then y; at least 3 vertices): their x between its ends, above its lower chain
    # and below its upper one, each edge found by a binary search on x.
    k = len(ring)
    r = 0  # the ring's rightmost (then highest) vertex ends the lower chain
    for t in range(k):
        i, j = ring[t], ring[r]
        if x[i] > x[j] or (x[i] == x[j] and y[i] > y[j]):
            r = t
    # Explicit loops, not fancy indexing: it compiles in a fraction of the time.
    lower = np.empty(r + 1, np.int64)
    lx = np.empty(r + 1)
    for t in range(r + 1):
        lower[t] = ring[t]
        lx[t] = x[ring[t]]
    upper = np.empty(k - r + 1, np.int64)
    ux = np.empty(k - r + 1)
    for t in range(k - r + 1):
        upper[t] = ring[r + t] if r + t < k else ring[0]
        ux[t] = x[upper[t]]
    x_lo, x_hi = lx[0], lx[r]
    keep = np.empty(len(cand), np.int64)
    m = 0
    for t in range(len(cand)):
        i = cand[t]
        px, py = x[i], y[i]
        inside = (x_lo < px) and (px < x_hi)
        if inside:
            a = _last_at_most(lx, px, False)
            la, lb = lower[a], lower[a + 1]
            inside = _cross(x[la], y[la], x[lb], y[lb], px, py) > 0.0
        if inside:
            a = _last_at_most(ux, px, True)
            ua, ub = upper[a], upper[a + 1]
            inside = _cross(x[ua], y[ua], x[ub], y[ub], px, py) > 0.0
        if not inside:
            keep[m] = i
            m += 1
    return keep[:m]


@njit(cache=True, nogil=True)
def _hulls(points: np.ndarray, begin: np.ndarray, end: np.ndarray) -> tuple:
    n_clusters = len(begin)
    ring_starts = np.zeros(n_clusters + 1, np.int64)
    # A ring has at most as many vertices as its cluster has points.
    total = 0
    for c in range(n_clusters):
        total += max(end[c] - begin[c], 0)
    rings = np.empty(total, np.int64)
    pos = 0
    for c in range(n_clusters):
        a, b = begin[c], end[c]
        ring_starts[c] = pos
        if b <= a:
            continue
        x = np.empty(b - a)
        y = np.empty(b - a)
        for i in range(b - a):
            x[i] = points[a + i, 0]
            y[i] = points[a + i, 1]
        cand = _survivors(x, y)
        if len(cand) > _SAMPLE_ABOVE:
            # A ring of walls leaves most of its points outside the octagon: the hull of an
            # even sample of them (a polygon of hull points too) drops most of the rest before
            # the sort.
            step = len(cand) // _SAMPLE
            sample = np.empty((len(cand) + step - 1) // step, np.int64)
            for t in range(len(sample)):
                sample[t] = cand[t * step]
            rough = _sorted_hull(x, y, sample)
            if len(rough) >= 3:
                cand = _outside(x, y, cand, rough)
        ring = _sorted_hull(x, y, cand)
        for t in range(len(ring)):
            rings[pos + t] = ring[t] + a
        pos += len(ring)
    ring_starts[n_clusters] = pos
    return rings[:pos], ring_starts


def footprint_hulls(
    points: np.ndarray, begin: np.ndarray, end: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The x, y convex hull of each cluster of ``points`` (P, 2 or more) float64, metres,
    whose cluster c is rows ``begin[c]:end[c]`` (begin, end (C,) int64).

    Returns (rows (V,) int64, ring_starts (C + 1,) int64): cluster c's hull is
    ``points[rows[ring_starts[c]:ring_starts[c + 1]], :2]``, counter-clockwise from its lowest
    x (then y); see the module for degenerate clusters (an empty one has an empty ring).
    Raises ValueError on a wrong shape or rows outside the points."""
    # Contiguous always: a column view (``runs[:, 0]``) would compile a second specialisation,
    # loaded on the node's first real scan instead of in its warm-up.
    pts = np.ascontiguousarray(points, dtype=np.float64)
    lo = np.ascontiguousarray(begin, dtype=np.int64)
    hi = np.ascontiguousarray(end, dtype=np.int64)
    if pts.ndim != 2 or pts.shape[1] < 2 or lo.ndim != 1 or lo.shape != hi.shape:
        raise ValueError(
            f"footprint_hulls: points (P, 2+), begin and end (C,); got {pts.shape}, "
            f"{lo.shape}, {hi.shape}"
        )
    if len(lo) and (lo.min() < 0 or hi.max() > len(pts) or (hi < lo).any()):
        raise ValueError("footprint_hulls: each cluster's rows must lie within the points")
    return _hulls(pts, lo, hi)


@warmer
def _warm() -> None:
    footprint_hulls(np.eye(3), np.array([0]), np.array([3]))
