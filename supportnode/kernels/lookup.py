"""Support look-up: the surface under each point from the stacked footprint rasters of
`geometry.objects.support_lookup._SupportTable`, in one compiled pass over the points (the
numpy version made eight (M,) temporaries). Releases the interpreter lock."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["table_lookup"]


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


@warmer
def _warm() -> None:
    best = np.full((2, 2, 2), -1, np.int32)
    best[1, 0, 0] = 0
    cp = np.array([[0.01, 0.01, 0.5], [0.5, 0.5, 0.0]])
    table_lookup(cp, np.array([0.2]), np.array([0.1, 0.1]), np.zeros(2, np.int64), best)
