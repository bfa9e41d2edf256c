"""One scan's voxels for the map's merge: each point's voxel, the voxels' counts and moments,
the points' offsets from their voxel's corner; in one pass, without sorting the points.

The voxels are ranked by their linear key in the scan's box (x slowest), i.e. ascending keys;
each voxel's moments are summed in input order, exactly as ``numpy.bincount`` with weights
sums them (the same bits as the map's numpy path). Releases the interpreter lock.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["scan_voxels"]
# OUTER_INDEX of supportnode.geometry.voxels: xx, yy, zz, xy, xz, yz.
_PAIRS = np.array([[0, 0], [1, 1], [2, 2], [0, 1], [0, 2], [1, 2]], np.int64)


@njit(cache=True, nogil=True)
def _scan_voxels(x, y, z, size, lo, dims, pairs, mark, rank, lin, local):
    n = x.size
    # Finite points only, checked here (before mark is touched) rather than by three numpy
    # passes and their temporaries.
    for i in range(n):
        if not (math.isfinite(x[i]) and math.isfinite(y[i]) and math.isfinite(z[i])):
            return None
    for i in range(n):
        kx = math.floor(x[i] / size)
        ky = math.floor(y[i] / size)
        kz = math.floor(z[i] / size)
        # As the numpy path: ((kx - lo0) * d1 + ky - lo1) * d2 + kz - lo2, in float64.
        f = (kx - lo[0]) * dims[1]
        f = f + ky
        f = f - lo[1]
        f = f * dims[2]
        f = f + kz
        f = f - lo[2]
        lin[i] = np.int64(f)
        local[0, i] = x[i] - kx * size
        local[1, i] = y[i] - ky * size
        local[2, i] = z[i] - kz * size
    nvox = 0
    for i in range(n):
        k = lin[i]
        if not mark[k]:
            mark[k] = True
            nvox += 1
    keys = np.empty((nvox, 3), np.int64)
    d0, d1, d2 = np.int64(dims[0]), np.int64(dims[1]), np.int64(dims[2])
    o0, o1, o2 = np.int64(lo[0]), np.int64(lo[1]), np.int64(lo[2])
    v = 0
    k = 0
    # Ascending keys, each from the loop's indices (no division of the linear keys
    # afterwards); the table is left all False again.
    for i0 in range(d0):
        if v == nvox:
            break
        for i1 in range(d1):
            if v == nvox:
                break
            for i2 in range(d2):
                if mark[k]:
                    mark[k] = False
                    rank[k] = v
                    keys[v, 0] = i0 + o0
                    keys[v, 1] = i1 + o1
                    keys[v, 2] = i2 + o2
                    v += 1
                k += 1
    voxel = np.empty(n, np.intp)
    counts = np.zeros(nvox, np.int64)
    moments = np.zeros((nvox, 9))
    for i in range(n):
        v = rank[lin[i]]
        voxel[i] = v
        counts[v] += 1
        for a in range(3):
            moments[v, a] += local[a, i]
        for c in range(6):
            moments[v, 3 + c] += local[pairs[c, 0], i] * local[pairs[c, 1], i]
    return keys, voxel, counts, moments


def scan_voxels(
    cols: list[np.ndarray],
    size: float,
    lo: np.ndarray,
    dims: np.ndarray,
    scratch: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """The voxels of (N,) float64 x, y, z columns (finite, metres) of edge ``size`` whose
    floored keys lie in the box ``lo`` (3,) float (the keys' minima) with ``dims`` (3,) float
    keys per axis: keys (V, 3) int64 ascending, each point's voxel (N,) intp, counts (V,),
    moments (V, 9) (sums then outer products in ``OUTER_INDEX`` order, relative to each
    voxel's corner) and the points' offsets from their corner (three (N,) views of
    ``scratch``). scratch: (mark (T,) bool all False, rank (T,) int64, lin (N,) int64, local
    (3, N) float64), T >= the box's voxels: kept by the caller across scans (fresh megabytes
    cost a page fault per 4 KB); mark is left all False."""
    if not (math.isfinite(size) and size > 0):
        raise ValueError(f"voxel size must be positive and finite, got {size}")
    x, y, z = (np.ascontiguousarray(c, dtype=np.float64) for c in cols)
    n = len(x)
    if not (len(y) == n == len(z)):
        raise ValueError("the three columns must have one length")
    mark, rank, lin, local = scratch
    top = float(np.prod(dims))
    if len(mark) < top or len(rank) < top or len(lin) < n or local.shape[1] < n:
        raise ValueError("scratch arrays smaller than the box or the scan")
    lo = np.asarray(lo, np.float64)
    dims = np.asarray(dims, np.float64)
    found = _scan_voxels(x, y, z, float(size), lo, dims, _PAIRS, mark, rank, lin, local)
    if found is None:
        raise ValueError("points must be finite (the map drops the others first)")
    keys, voxel, counts, moments = found
    return keys, voxel, counts, moments, [local[0, :n], local[1, :n], local[2, :n]]


@warmer
def _warm() -> None:
    cols = [np.array([0.0, 0.07]), np.array([0.0, 0.0]), np.array([0.0, 0.01])]
    scratch = (
        np.zeros(4, np.bool_),
        np.zeros(4, np.int64),
        np.zeros(2, np.int64),
        np.zeros((3, 2)),
    )
    scan_voxels(cols, 0.05, np.zeros(3), np.array([2.0, 1.0, 1.0]), scratch)
