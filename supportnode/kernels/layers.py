"""Levels of a sparse cluster: the heights where a horizontal face may hold what stands on it
(`geometry.objects.layers`), and which of them are worth a closer look, in one pass over the
cluster's points sorted by height. A lidar's cluster has a level at every scan line; the
numpy version took ~25 small array operations a cluster, ~3 ms of a node's detection.
Releases the interpreter lock.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer
from supportnode.kernels.search import first_above, first_at

__all__ = ["may_hold", "screen_levels"]


@njit(cache=True, nogil=True)
def _screen(z, xy, edges, clear, slab, min_window, min_up, min_out):
    n = z.size
    nb = edges.size - 1
    count = np.zeros(nb, np.int64)
    prev = first_at(z, edges[0], 0)
    for k in range(nb):  # np.histogram's bins: [a, b), the last one [a, b]
        if k == nb - 1:
            nxt = first_above(z, edges[k + 1], prev)
        else:
            nxt = first_at(z, edges[k + 1], prev)
        count[k] = nxt - prev
        prev = nxt
    # Windows around bins 1 .. nb - 2; local maxima (>= left, > right; -1 beyond the ends).
    nw = nb - 2
    window = np.empty(max(nw, 0), np.int64)
    for k in range(nw):
        window[k] = count[k] + count[k + 1] + count[k + 2]
    peaks = 0
    levels = np.empty(max(nw, 0))
    for k in range(nw - 1, -1, -1):  # highest first
        left = window[k - 1] if k > 0 else -1
        right = window[k + 1] if k + 1 < nw else -1
        if window[k] >= left and window[k] > right and window[k] >= min_window:
            levels[peaks] = (edges[k + 1] + edges[k + 2]) / 2.0
            peaks += 1
    levels = levels[:peaks]
    a = np.empty(peaks, np.int64)
    b = np.empty(peaks, np.int64)
    u = np.empty(peaks, np.int64)
    whole = np.zeros(peaks, np.bool_)
    # The x, y box of the rows from each row up.
    lo = np.empty((n, 2))
    hi = np.empty((n, 2))
    if peaks == 0:
        return levels, a, b, u, whole, lo[:0], hi[:0]
    lo[n - 1] = xy[n - 1]
    hi[n - 1] = xy[n - 1]
    for r in range(n - 2, -1, -1):
        for d in range(2):
            lo[r, d] = min(xy[r, d], lo[r + 1, d])
            hi[r, d] = max(xy[r, d], hi[r + 1, d])
    for i in range(peaks):
        a[i] = first_above(z, levels[i] - 1.5 * slab, 0)
        b[i] = first_above(z, levels[i] + 1.5 * slab, a[i])
        u[i] = first_above(z, levels[i] + clear, 0)
        if a[i] >= b[i] or u[i] >= n or n - u[i] < min_up:
            continue
        out = 0
        for r in range(a[i], b[i]):
            inside = True
            for d in range(2):
                if xy[r, d] < lo[u[i], d] - slab or xy[r, d] > hi[u[i], d] + slab:
                    inside = False
            if not inside:
                out += 1
        whole[i] = out >= min_out
    return levels, a, b, u, whole, lo, hi


@njit(cache=True, nogil=True)
def _may_hold(p, slab, clear, min_up, min_out):
    n = p.shape[0]
    zmin, zmax = np.inf, -np.inf
    for r in range(n):
        zmin = min(zmin, p[r, 2])
        zmax = max(zmax, p[r, 2])
    nb = int((zmax - zmin) / slab) + 1
    lo = np.full((nb + 1, 2), np.inf)  # row nb: above everything, an empty box
    hi = np.full((nb + 1, 2), -np.inf)
    up = np.zeros(nb + 1, np.int64)
    k_of = np.empty(n, np.int64)
    for r in range(n):
        k = min(int((p[r, 2] - zmin) / slab), nb - 1)
        k_of[r] = k
        up[k] += 1
        for d in range(2):
            lo[k, d] = min(lo[k, d], p[r, d])
            hi[k, d] = max(hi[k, d], p[r, d])
    for k in range(nb - 1, -1, -1):  # suffixes: the rows from bin k up
        up[k] += up[k + 1]
        for d in range(2):
            lo[k, d] = min(lo[k, d], lo[k + 1, d])
            hi[k, d] = max(hi[k, d], hi[k + 1, d])
    # A point of bin k lies in the slab of levels L < e_k + 2.5 slab only, and what rises
    # above such a level's clearance includes all of bins k + reach up: their box is inside
    # that level's box, and a point outside the larger box is outside the smaller one. One
    # bin of margin each way for rounding.
    reach = math.ceil(2.5 + clear / slab) + 1
    highest = zmax - clear + 1.5 * slab  # no level's slab reaches above
    out = 0
    for r in range(n):
        k = k_of[r]
        if p[r, 2] > highest + slab or up[max(k - 1, 0)] < min_up:
            continue
        j = min(k + reach, nb)
        inside = True
        for d in range(2):
            if p[r, d] < lo[j, d] - slab or p[r, d] > hi[j, d] + slab:
                inside = False
        if not inside:
            out += 1
            if out >= min_out:
                return True
    return False


def may_hold(p: np.ndarray, slab: float, clear: float, min_up: float, min_out: float) -> bool:
    """Whether any level of the cluster p (P, 3) float64 (metres, any order) might be worth
    trying (see :func:`screen_levels`): False only when none can be, from boxes of 5 mm bins
    in one pass, without sorting; a lidar's single box (each line inside the box of what is
    above it) is done here."""
    p = np.ascontiguousarray(p, np.float64).reshape(-1, 3)
    if len(p) == 0 or not slab > 0:
        return False
    return bool(_may_hold(p, float(slab), float(clear), float(min_up), float(min_out)))


def screen_levels(
    z: np.ndarray,
    xy: np.ndarray,
    bottom: float,
    top: float,
    clear: float,
    slab: float,
    min_window: int,
    min_up: float,
    min_out: float,
) -> tuple[np.ndarray, ...]:
    """A cluster's levels and which to try. z (P,) float64 heights ascending, xy (P, 2)
    float64 the same rows' x, y (metres). The histogram of z in bins of ``slab`` from
    ``bottom - slab`` up to ``top``: a level is the centre of a bin whose three-bin window
    holds at least ``min_window`` points, no fewer than the window below it and more than
    the one above (levels (L,), highest first). For each: a, b (L,) int64 its slab's rows
    (z within 1.5 slab), u (L,) the first row above ``level + clear``, and whole (L,) bool:
    at least ``min_up`` rows above u and at least ``min_out`` of the slab's points outside
    the x, y box of the rows from u up grown by ``slab``; and lo, hi (P, 2) that box for
    every row (the rows from it up; (0, 2) when there is no level)."""
    z = np.ascontiguousarray(z, np.float64)
    xy = np.ascontiguousarray(xy, np.float64).reshape(-1, 2)
    if xy.shape[0] != z.size:
        raise ValueError(f"xy must have one row per height ({z.size}), got {xy.shape[0]}")
    if z.size > 1 and np.any(np.diff(z) < 0):
        raise ValueError("heights must ascend")
    if not slab > 0:
        raise ValueError(f"slab must be positive, got {slab}")
    edges = np.arange(bottom - slab, top + slab, slab)
    if top <= bottom or len(edges) < 4 or z.size == 0 or not math.isfinite(clear):
        empty = np.zeros(0, np.int64)
        box = np.zeros((0, 2))
        return np.zeros(0), empty, empty.copy(), empty.copy(), np.zeros(0, bool), box, box.copy()
    # Counts as float64 (exact for any count): an int or a float min_up would be two
    # specialisations, each loaded from the cache (~8 ms) by a fresh process.
    return _screen(
        z, xy, edges, float(clear), float(slab), int(min_window), float(min_up), float(min_out)
    )


@warmer
def _warm() -> None:
    z = np.linspace(0.0, 0.2, 40)
    xy = np.zeros((40, 2))
    screen_levels(z, xy, 0.0, 0.18, 0.015, 0.005, 5, 5.0, 1.0)
    may_hold(np.c_[xy, z], 0.005, 0.015, 5.0, 1.0)
