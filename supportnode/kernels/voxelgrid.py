"""Points grouped into a dense voxel grid: keys, a counting sort, corner offsets and moments.

The compiled form of :func:`supportnode.geometry.voxels.voxelize` where the grid's extent is
small enough to count in (a room at 10 cm is ~1e5 cells): numpy needs a dozen passes (keys,
bincount, rank, a radix argsort, three gathers, nine reduceat) where two loops suffice.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True)
def _bounds(pts: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    bad = 0
    for i in range(pts.shape[0]):
        for a in range(3):
            q = np.floor(pts[i, a] / size[a])
            if not abs(q) < np.inf:  # NaN fails every comparison
                bad += 1
                break
            lo[a] = min(lo[a], q)
            hi[a] = max(hi[a], q)
    return lo, hi, bad


@njit(cache=True)
def _count(
    pts: np.ndarray, size: np.ndarray, origin: np.ndarray, dims: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    n = pts.shape[0]
    # Each point's linear key, later (in place: fresh pages cost more than the arithmetic
    # on them) its voxel.
    lin = np.empty(n, np.int64)
    # Points per cell, then (read at occupied cells only) the voxel number of each cell.
    occupied = np.zeros(dims[0] * dims[1] * dims[2], np.int64)
    for i in range(n):
        c = 0
        for a in range(3):
            f = np.floor(pts[i, a] / size[a]) - origin[a]
            # In float first: NaN fails, and no key out of the table is ever formed.
            if not (0 <= f < dims[a]):
                return lin, occupied, False
            c = c * dims[a] + np.int64(f)
        lin[i] = c
        occupied[c] += 1
    return lin, occupied, True


@njit(cache=True)
def _group(
    pts: np.ndarray,
    size: np.ndarray,
    origin: np.ndarray,
    dims: np.ndarray,
    point_voxel: np.ndarray,
    occupied: np.ndarray,
):
    n = pts.shape[0]
    d1, d2 = dims[1], dims[2]
    m = 0
    for c in range(occupied.size):
        if occupied[c]:
            m += 1
    keys = np.empty((m, 3), np.int64)
    counts = np.empty(m, np.int64)
    starts = np.empty(m, np.int64)
    v, s = 0, 0
    for c in range(occupied.size):  # ascending linear key: the voxels' order
        cnt = occupied[c]
        if cnt:
            counts[v], starts[v] = cnt, s
            s += cnt
            occupied[c] = v
            rem, kz = divmod(c, d2)
            kx, ky = divmod(rem, d1)
            keys[v, 0], keys[v, 1], keys[v, 2] = kx + origin[0], ky + origin[1], kz + origin[2]
            v += 1
    fill = starts.copy()
    order = np.empty(n, np.int64)
    for i in range(n):  # a stable counting sort: input order within each voxel
        v = occupied[point_voxel[i]]
        point_voxel[i] = v
        order[fill[v]] = i
        fill[v] += 1
    # Then voxel by voxel in sorted order: reads of the points gathered, every write
    # sequential, the moments summed in registers (scattered writes cost 3x this).
    local = np.empty((3, n), np.float64)
    sums = np.empty((m, 3), np.float64)
    outer = np.empty((m, 6), np.float64)
    s0, s1, s2 = size[0], size[1], size[2]
    for v in range(m):
        sx = sy = sz = xx = yy = zz = xy = xz = yz = 0.0
        for j in range(starts[v], starts[v] + counts[v]):
            i = order[j]
            # As numpy computes them: p - floor(p / s) * s, bit for bit.
            x = pts[i, 0] - np.floor(pts[i, 0] / s0) * s0
            y = pts[i, 1] - np.floor(pts[i, 1] / s1) * s1
            z = pts[i, 2] - np.floor(pts[i, 2] / s2) * s2
            local[0, j], local[1, j], local[2, j] = x, y, z
            sx += x
            sy += y
            sz += z
            xx += x * x
            yy += y * y
            zz += z * z
            xy += x * y
            xz += x * z
            yz += y * z
        sums[v, 0], sums[v, 1], sums[v, 2] = sx, sy, sz
        outer[v, 0], outer[v, 1], outer[v, 2] = xx, yy, zz
        outer[v, 3], outer[v, 4], outer[v, 5] = xy, xz, yz
    return keys, counts, point_voxel, order, starts, local, sums, outer


def voxel_bounds(points: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Per-axis least and greatest voxel key floor(p / size) of (N, 3) float64 points, as
    (3,) float64 each (inf / -inf when empty), and how many rows hold a NaN or an inf."""
    pts, sz = _check(points, size)
    lo, hi, bad = _bounds(pts, sz)
    return lo, hi, int(bad)


def group_dense(
    points: np.ndarray, size: np.ndarray, origin: np.ndarray, dims: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Group finite (N, 3) float64 points (metres) into voxels of ``size`` (3,) m.

    origin: (3,) int64, the least key on each axis; dims: (3,) int64 extent in voxels, so that
    every key lies in ``origin + [0, dims)`` (from :func:`voxel_bounds`); the grid's
    prod(dims) cells are counted in one table. Returns, voxels in ascending key order
    (lexicographic x, y, z): keys (M, 3) int64, counts (M,) int64, point_voxel (N,) int64,
    order (N,) int64 (a stable sort of the points by voxel), starts (M,) int64, local (3, N)
    float64 (each point's offset from its voxel's corner, in ``order``), sums (M, 3) and outer
    (M, 6) float64 (sums of the offsets and of their products xx, yy, zz, xy, xz, yz).
    Raises ValueError on a wrong shape, a non-finite point or a key outside the extent
    (checked as the points are counted: no separate pass).
    """
    pts, sz = _check(points, size)
    o = np.ascontiguousarray(origin, dtype=np.int64).reshape(3)
    d = np.ascontiguousarray(dims, dtype=np.int64).reshape(3)
    if (d < 1).any() or float(np.prod(d.astype(np.float64))) >= 2.0**62:
        raise ValueError(f"dims must be positive with a product below 2^62, got {d.tolist()}")
    lin, occupied, ok = _count(pts, sz, o, d)
    if not ok:
        raise ValueError("a point is not finite or lies outside the grid of origin and dims")
    return _group(pts, sz, o, d, lin, occupied)


def _check(points: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    sz = np.ascontiguousarray(size, dtype=np.float64).reshape(3)
    if not (np.isfinite(sz).all() and (sz > 0).all()):
        raise ValueError(f"voxel size must be positive and finite, got {sz.tolist()}")
    return pts, sz


@warmer
def _warm() -> None:
    pts = np.array([[0.0, 0.0, 0.0], [0.25, 0.1, 0.05]])
    size = np.array([0.1, 0.1, 0.05])
    group_dense(pts, size, np.zeros(3, np.int64), np.array([3, 2, 2]))
    voxel_bounds(pts, size)
