"""For the levels of a sparse cluster (`kernels.layers.screen_levels`), how many of each
level's points lie outside the turned box of what rises above it (`geometry.objects.rising`),
in one compiled pass from the highest level down.

What rises above a level is a suffix of the cluster's rows (sorted by height), each level's
containing the one above's: its hull is the hull of the previous hull and the rows between
the two levels (Andrew's monotone chain on those few points), its turned box the smallest of
the rectangles flush with one of the hull's edges. A lidar's cluster has a level at every
scan line; a hull and a box per level from numpy took ~7 ms a node's scan.

xy (P, 2) float64 metres, the cluster's points by height; rows as `screen_levels` gives them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.hull import _COLLINEAR, _sorted_hull
from supportnode.kernels.runtime import warmer

__all__ = ["outside_turned"]


@njit(cache=True, nogil=True)
def _hull(px, py):  # type: ignore[no-untyped-def]
    """Hull vertices (counter-clockwise, no collinear ones) of the points px, py (K,)."""
    # kernels.hull's own sort and chain: numba's generic sorts and fancy indexing cost a
    # fresh install seconds of compiling.
    return _sorted_hull(px, py, np.arange(len(px)))


@njit(cache=True, nogil=True)
def _holds(hx, hy, x, y):  # type: ignore[no-untyped-def]
    # Whether the hull hx, hy (counter-clockwise, >= 3 vertices) holds (x, y), its edges
    # included up to round-off (as `kernels.hull`'s collinear test): it stays the same hull.
    h = len(hx)
    if h < 3:
        return False
    for j in range(h):
        k = (j + 1) % h
        ux, uy, vx, vy = hx[k] - hx[j], hy[k] - hy[j], x - hx[j], y - hy[j]
        if ux * vy - uy * vx < -_COLLINEAR * (abs(ux) + abs(uy)) * (abs(vx) + abs(vy)):
            return False
    return True


@njit(cache=True, nogil=True)
def _extent(hx, hy, c, s):  # type: ignore[no-untyped-def]
    # The hull's u min, u max, v min, v max in the axes (c, s), (-s, c), over all vertices.
    ul, uh, vl, vh = np.inf, -np.inf, np.inf, -np.inf
    for j in range(len(hx)):
        uu, vv = hx[j] * c + hy[j] * s, -hx[j] * s + hy[j] * c
        ul, uh, vl, vh = min(ul, uu), max(uh, uu), min(vl, vv), max(vh, vv)
    return ul, uh, vl, vh


@njit(cache=True, nogil=True)
def _box(hx, hy):  # type: ignore[no-untyped-def]
    """The smallest rectangle flush with an edge of the hull hx, hy (H,) (counter-clockwise):
    (cos, sin of its first axis, u min, u max, v min, v max) in its axes. Rotating calipers:
    the vertices farthest along, against and across each edge move on as the edges turn, so
    all H boxes take O(H) (a dense cluster's hull has hundreds of vertices, and a level each
    5 mm: every vertex against every edge cost ~20 ms a 539k-point shelf)."""
    h = len(hx)
    if h < 3:  # a point or a segment: along it
        c, s = 1.0, 0.0
        if h == 2 and (hx[1] != hx[0] or hy[1] != hy[0]):
            norm = np.hypot(hx[1] - hx[0], hy[1] - hy[0])
            c, s = (hx[1] - hx[0]) / norm, (hy[1] - hy[0]) / norm
        ul, uh, vl, vh = _extent(hx, hy, c, s)
        return c, s, ul, uh, vl, vh
    best = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    best_area = np.inf
    far = lo = hi = 0  # the vertices farthest across, against and along the edge
    for e in range(h):
        dx, dy = hx[(e + 1) % h] - hx[e], hy[(e + 1) % h] - hy[e]
        norm = np.hypot(dx, dy)
        c, s = dx / norm, dy / norm
        if e == 0:  # the calipers' start: every vertex looked at once
            ul, uh, _, vh = _extent(hx, hy, c, s)
            for j in range(h):
                if hx[j] * c + hy[j] * s == uh:
                    hi = j
                if hx[j] * c + hy[j] * s == ul:
                    lo = j
                if -hx[j] * s + hy[j] * c == vh:
                    far = j
        for _ in range(h):  # then each moves on while the next vertex lies further
            k = (hi + 1) % h
            if hx[k] * c + hy[k] * s < hx[hi] * c + hy[hi] * s:
                break
            hi = k
        for _ in range(h):
            k = (far + 1) % h
            if -hx[k] * s + hy[k] * c < -hx[far] * s + hy[far] * c:
                break
            far = k
        for _ in range(h):
            k = (lo + 1) % h
            if hx[k] * c + hy[k] * s > hx[lo] * c + hy[lo] * s:
                break
            lo = k
        ul, uh = hx[lo] * c + hy[lo] * s, hx[hi] * c + hy[hi] * s
        vl, vh = -hx[e] * s + hy[e] * c, -hx[far] * s + hy[far] * c
        area = (uh - ul) * (vh - vl)
        if area < best_area:
            best_area = area
            best = (c, s, ul, uh, vl, vh)
    return best


@njit(cache=True, nogil=True)
def _outside(xy, a, b, u, slab):  # type: ignore[no-untyped-def]
    n = xy.shape[0]
    out = np.zeros(len(u), np.int64)
    hx = np.empty(0)
    hy = np.empty(0)
    lo0 = lo1 = np.inf
    hi0 = hi1 = -np.inf
    c, s, ul, uh, vl, vh = _box(hx, hy)
    top = n  # rows [top, n) are in the hull so far
    for i in range(len(u)):  # levels highest first: u does not increase
        start = u[i]
        grown = False
        for r in range(start, top):  # a dense cluster's next rows mostly lie on its hull
            if not _holds(hx, hy, xy[r, 0], xy[r, 1]):
                grown = True
                break
        if grown:
            m = len(hx) + top - start
            px, py = np.empty(m), np.empty(m)
            for j in range(len(hx)):
                px[j], py[j] = hx[j], hy[j]
            for r in range(start, top):
                px[len(hx) + r - start], py[len(hx) + r - start] = xy[r, 0], xy[r, 1]
                lo0, hi0 = min(lo0, xy[r, 0]), max(hi0, xy[r, 0])
                lo1, hi1 = min(lo1, xy[r, 1]), max(hi1, xy[r, 1])
            keep = _hull(px, py)
            hx, hy = np.empty(len(keep)), np.empty(len(keep))
            for j in range(len(keep)):
                hx[j], hy[j] = px[keep[j]], py[keep[j]]
            c, s, ul, uh, vl, vh = _box(hx, hy)
        top = min(top, start)
        if len(hx) == 0:
            continue
        count = 0
        for r in range(a[i], b[i]):
            x, y = xy[r, 0], xy[r, 1]
            uu, vv = x * c + y * s, -x * s + y * c
            inside = lo0 - slab <= x <= hi0 + slab and lo1 - slab <= y <= hi1 + slab
            inside = inside and ul - slab <= uu <= uh + slab and vl - slab <= vv <= vh + slab
            count += not inside
        out[i] = count
    return out


def outside_turned(
    xy: np.ndarray, a: np.ndarray, b: np.ndarray, u: np.ndarray, slab: float
) -> np.ndarray:
    """(L,) int64: for each level (rows [a, b) its slab, u the first row of what rises above
    it; u not increasing: highest level first) how many of its slab's points lie outside the
    x, y box or the turned box of rows [u, P), each grown by ``slab`` m. xy: (P, 2) float64."""
    xy = np.ascontiguousarray(xy, np.float64).reshape(-1, 2)
    a, b, u = (np.ascontiguousarray(v, np.int64) for v in (a, b, u))
    if len(u) > 1 and np.any(np.diff(u) > 0):
        raise ValueError("levels must come highest first (u not increasing)")
    if len(u) and (u.min() < 0 or u.max() > len(xy) or a.min() < 0 or b.max() > len(xy)):
        raise ValueError("level rows outside the points")
    return _outside(xy, a, b, u, float(slab))


@warmer
def _warm() -> None:
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.5]])
    outside_turned(xy, np.array([0]), np.array([2]), np.array([2]), 0.005)
