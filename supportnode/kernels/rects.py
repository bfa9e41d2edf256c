"""Minimum-area yaw boxes of many footprint polygons in one compiled pass.

For each polygon (a convex hull, counter-clockwise) and each of its edge directions, the
extents of its vertices along the direction and across it; the direction whose box has the
least area wins (ties: the first). numpy did it on padded (B, K, K) stacks, some 20 calls and
megabytes of temporaries a detection; here two loops per polygon, the same arithmetic
(u = x cos + y sin, v = -x sin + y cos, area + 1e-12 angle), so the same choice and extents.
The directions' angles, cosines and sines stay numpy's (its SIMD functions round differently
from the C library's). Releases the interpreter lock.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["min_area_boxes"]


@njit(cache=True, nogil=True)
def _boxes(x, y, starts, angles, cos, sin):
    n = len(starts) - 1
    best = np.empty(n, np.int64)
    ext = np.empty((n, 4))  # u max, u min, v max, v min at the best direction
    for j in range(n):
        a, b = starts[j], starts[j + 1]
        best_score = np.inf
        best[j] = a
        for t in range(a, b):  # each edge's direction
            c, s = cos[t], sin[t]
            u_max, u_min, v_max, v_min = -np.inf, np.inf, -np.inf, np.inf
            for i in range(a, b):
                u = x[i] * c + y[i] * s
                v = -x[i] * s + y[i] * c
                u_max, u_min = max(u_max, u), min(u_min, u)
                v_max, v_min = max(v_max, v), min(v_min, v)
            score = (u_max - u_min) * (v_max - v_min) + 1e-12 * angles[t]
            if t == a or score < best_score:
                best_score = score
                best[j] = t
                ext[j, 0], ext[j, 1], ext[j, 2], ext[j, 3] = u_max, u_min, v_max, v_min
    return best, ext


def min_area_boxes(
    x: np.ndarray,
    y: np.ndarray,
    starts: np.ndarray,
    angles: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """For polygons whose vertices are rows ``starts[j]:starts[j + 1]`` of x, y (N,) float64
    (metres; each polygon at least one vertex), and one direction per vertex (its edge's
    ``angles``, ``cos``, ``sin``, (N,) float64): each polygon's chosen direction (J,) int64
    (a row) and the extents there (J, 4): max and min of u, then of v."""
    cols = [np.ascontiguousarray(c, dtype=np.float64) for c in (x, y, angles, cos, sin)]
    st = np.ascontiguousarray(starts, dtype=np.int64)
    n = len(cols[0])
    if any(len(c) != n for c in cols) or st.ndim != 1 or len(st) < 1:
        raise ValueError("min_area_boxes: x, y, angles, cos, sin (N,) and starts (J + 1,)")
    if st[0] != 0 or st[-1] != n or (np.diff(st) < 1).any():
        raise ValueError("min_area_boxes: starts must rise from 0 to N, each polygon non-empty")
    return _boxes(cols[0], cols[1], st, cols[2], cols[3], cols[4])


@warmer
def _warm() -> None:
    z = np.array([0.0, 1.0, 0.0])
    min_area_boxes(z, np.array([0.0, 0.0, 1.0]), np.array([0, 3]), z, z + 1.0, z)
