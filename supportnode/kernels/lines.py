"""The points of a cloud that may be 3-D hull vertices as far as vertical lines tell.

A point strictly between two points of exactly the same x, y lies on the vertical segment
joining them and is never a vertex of the convex hull (see
`geometry.objects.hull._hull_candidates`). The points are grouped as numpy grouped them: by
a 32-bit hash of their x, y bits, stable in input order, each run of equal x, y bits in that
order one line (a hash collision splits a line into runs and keeps more), with its least and
greatest z (NaN propagating). One pass with a hash table of the hashes instead of two radix
sorts, gathers and reductions: 10x faster on a depth camera's clusters, where no point lies
on another's line.
"""

from __future__ import annotations

import numpy as np
from numba import njit, uint64

from supportnode.kernels.runtime import warmer

__all__ = ["column_ends"]

# Odd 64-bit multipliers (golden ratio and a splitmix64 constant) hashing x, y bit patterns.
HASH_X = np.uint64(0x9E3779B97F4A7C15)
HASH_Y = np.uint64(0xBF58476D1CE4E5B9)


@njit(cache=True, nogil=True)
def _runs(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each point's run (P,) and each run's least and greatest z (R,), runs numbered in
    order of their first point."""
    n = x.size
    bits = 4
    while (1 << bits) < 2 * max(n, 1):
        bits += 1
    mask = (1 << bits) - 1
    slot_hash = np.full(mask + 1, -1, np.int64)  # the 32-bit hash of the group, -1: empty
    slot_run = np.empty(mask + 1, np.int64)  # the group's latest run
    run = np.empty(n, np.int64)
    lo = np.empty(n)
    hi = np.empty(n)
    first = np.empty(n, np.int64)  # each run's first point (its x, y bits)
    m = 0
    for i in range(n):
        h = np.int64(((x[i] * HASH_X) ^ (y[i] * HASH_Y)) >> uint64(32))
        pos = np.int64((uint64(h) * HASH_X) >> uint64(64 - bits))
        while slot_hash[pos] != -1 and slot_hash[pos] != h:
            pos = (pos + 1) & mask
        r = -1
        if slot_hash[pos] == h:
            r = slot_run[pos]
            if x[first[r]] != x[i] or y[first[r]] != y[i]:
                r = -1  # the group's previous point is on another line: a run of its own
        if r < 0:
            r = m
            m += 1
            slot_hash[pos], slot_run[pos] = h, r
            first[r], lo[r], hi[r] = i, z[i], z[i]
        else:
            # As numpy's minimum and maximum: a NaN, once met, stays.
            if z[i] < lo[r] or np.isnan(z[i]):
                lo[r] = z[i]
            if z[i] > hi[r] or np.isnan(z[i]):
                hi[r] = z[i]
        run[i] = r
    return run, lo[:m], hi[:m]


@njit(cache=True, nogil=True)
def _ends(z: np.ndarray, run: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    keep = np.empty(z.size, np.bool_)
    for i in range(z.size):
        keep[i] = not (z[i] > lo[run[i]] and z[i] < hi[run[i]])
    return keep


def column_ends(p: np.ndarray) -> np.ndarray:
    """(P,) bool: the points of p (P, 3) float64 that are no point strictly between the
    lowest and highest of their vertical line (exactly the same x, y bits)."""
    pts = np.ascontiguousarray(p, dtype=np.float64).reshape(-1, 3)
    bits = pts.view(np.uint64)  # x, y columns read in place
    z = pts[:, 2]
    run, lo, hi = _runs(bits[:, 0], bits[:, 1], z)
    return _ends(z, run, lo, hi)


@warmer
def _warm() -> None:
    column_ends(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.5], [1.0, 0.0, 0.0]]))
