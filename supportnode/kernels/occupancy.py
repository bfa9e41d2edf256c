"""The occupied voxels of an object candidate cloud on a dense grid, for its components.

`geometry.objects.clusters._cluster_voxel`'s first steps in two compiled passes: the points'
flat keys on a grid with an empty border, then the occupancy, the voxels' ids (ascending
keys, from a radix sort of the points' keys: the grid's millions of cells are never
scanned), each point's voxel and the highest surface under each voxel; what
`kernels.components.label_voxel_grid` takes. Integer work only: the same values as the numpy
steps it replaces. Releases the interpreter lock.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["grid_keys", "occupied_voxels"]


@njit(cache=True, nogil=True)
def _grid_keys(cp, size):
    m = cp.shape[0]
    lo = np.full(3, np.inf)
    for i in range(m):
        for a in range(3):
            lo[a] = min(lo[a], cp[i, a])
    ijk = np.empty((m, 3), np.int64)
    top = np.zeros(3, np.int64)
    for i in range(m):
        for a in range(3):
            # As ((c - c.min()) / size).astype(int64) + 1: truncation of a value >= 0.
            k = np.int64((cp[i, a] - lo[a]) / size) + 1
            ijk[i, a] = k
            top[a] = max(top[a], k)
    dims = top + 2
    keys = np.empty(m, np.int64)
    for i in range(m):
        keys[i] = (ijk[i, 0] * dims[1] + ijk[i, 1]) * dims[2] + ijk[i, 2]
    return keys, dims


@njit(cache=True, nogil=True)
def _sorted_unique(keys, cells):
    """The distinct keys ascending: an LSD radix sort (11-bit digits) of the keys, then the
    runs; O(M), without visiting the grid's cells."""
    m = keys.size
    a = np.empty(m, np.int64)
    for i in range(m):  # loops, not slice copies: those compile for seconds
        a[i] = keys[i]
    b = np.empty(m, np.int64)
    shift = 0
    while (cells - 1) >> shift:
        count = np.zeros(2049, np.int64)
        for i in range(m):
            count[((a[i] >> shift) & 2047) + 1] += 1
        for d in range(2048):
            count[d + 1] += count[d]
        for i in range(m):
            d = (a[i] >> shift) & 2047
            b[count[d]] = a[i]
            count[d] += 1
        a, b = b, a
        shift += 11
    nv = 0
    for i in range(m):
        if i == 0 or a[i] != a[i - 1]:
            a[nv] = a[i]
            nv += 1
    out = np.empty(nv, np.int64)
    for i in range(nv):
        out[i] = a[i]
    return out


@njit(cache=True, nogil=True)
def _occupied(keys, cells, support, with_support):
    vkeys = _sorted_unique(keys, cells)
    nv = vkeys.size
    occupied = np.zeros(cells, np.bool_)
    vid = np.empty(cells, np.int32)  # read at occupied keys only
    for v in range(nv):
        occupied[vkeys[v]] = True
        vid[vkeys[v]] = v
    of_point = np.empty(keys.size, np.int64)
    vsup = np.full(nv if with_support else 0, -1, np.int64)
    for i in range(keys.size):
        v = vid[keys[i]]
        of_point[i] = v
        if with_support and support[i] > vsup[v]:
            vsup[v] = support[i]
    return vkeys, occupied, vid, of_point, vsup


def grid_keys(cp: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Flat keys (M,) int64 of (M, 3) finite points (m; M >= 1) on a grid of cubes of edge
    ``size`` m anchored at their minimum, with one empty voxel of border each side, and the
    grid's dims (3,) int64 (x slowest)."""
    return _grid_keys(np.ascontiguousarray(cp, np.float64), float(size))


def occupied_voxels(
    keys: np.ndarray, cells: int, support: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """The occupied voxels of flat ``keys`` (M,) int64 in [0, cells): their keys (V,) int64
    ascending, the occupancy (cells,) bool, the voxel id at each occupied key (cells,) int32
    (other entries undefined), each point's voxel (M,) int64 and, with ``support`` (M,) int64
    (a surface id per point, -1 none), the highest one under each voxel (V,) (-1: none)."""
    keys = np.ascontiguousarray(keys, np.int64)
    if keys.size and (keys.min() < 0 or keys.max() >= cells):
        raise ValueError(f"keys must lie in [0, {cells})")
    if cells >= 2**31:
        raise ValueError("too many cells for int32 voxel ids")
    sup = np.zeros(0, np.int64) if support is None else np.ascontiguousarray(support, np.int64)
    if support is not None and sup.shape != keys.shape:
        raise ValueError(f"support must have one id per point ({keys.size}), got {sup.size}")
    vkeys, occ, vid, of_point, vsup = _occupied(keys, int(cells), sup, support is not None)
    return vkeys, occ, vid, of_point, (vsup if support is not None else None)


@warmer
def _warm() -> None:
    keys, dims = grid_keys(np.array([[0.0, 0.0, 0.0], [0.05, 0.01, 0.0]]), 0.02)
    occupied_voxels(keys, int(np.prod(dims)), np.array([-1, 0]))
    occupied_voxels(keys, int(np.prod(dims)))
