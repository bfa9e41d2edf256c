"""Voxel downsampling: count, centroid and covariance of the points in each occupied cube."""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

# Cell indices stay exact in float64 and far from int64 overflow below this.
_MAX_INDEX = 2.0**52


@njit(cache=True, nogil=True)
def _hash(i: int, j: int, k: int, mask: int) -> int:
    h = (i * 73856093) ^ (j * 19349663) ^ (k * 83492791)
    return h & mask


@njit(cache=True, nogil=True)
def _rehash(keys: np.ndarray, used: int, size: int) -> np.ndarray:
    slot = np.full(size, -1, np.int64)
    mask = size - 1
    for v in range(used):
        h = _hash(keys[v, 0], keys[v, 1], keys[v, 2], mask)
        while slot[h] >= 0:
            h = (h + 1) & mask
        slot[h] = v
    return slot


@njit(cache=True, nogil=True)
def _grow(a: np.ndarray) -> np.ndarray:
    out = np.zeros((2 * a.shape[0], a.shape[1]), a.dtype)
    # Element by element: a 2-D slice assignment costs ~3 s of compiling on a fresh install.
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            out[i, j] = a[i, j]
    return out


@njit(cache=True, nogil=True)
def _sums(points: np.ndarray, inv: float) -> np.ndarray:
    # Tables sized by the voxels found, not the points: a depth image of 300k pixels fills a
    # few thousand voxels of 5 cm, and page-faulting point-sized tables cost more than the pass.
    cap = 1024
    keys = np.empty((cap, 3), np.int64)
    # Per voxel: its first point, then sums of the offsets d from it (d, and the six products
    # d_a d_b), and the count. Offsets from a point inside the voxel keep the sums of squares
    # exact to rounding wherever the cloud lies.
    sums = np.zeros((cap, 13), np.float64)
    slot = np.full(2 * cap, -1, np.int64)  # open addressing, load <= 1/2
    mask = 2 * cap - 1
    used = 0
    n = points.shape[0]
    r = 0
    while r < n:
        x, y, z = points[r, 0], points[r, 1], points[r, 2]
        fx, fy, fz = x * inv, y * inv, z * inv
        # NaN fails every comparison: rows with a NaN, an inf or a huge coordinate are skipped.
        if not (abs(fx) < _MAX_INDEX and abs(fy) < _MAX_INDEX and abs(fz) < _MAX_INDEX):
            r += 1
            continue
        i, j, k = int(np.floor(fx)), int(np.floor(fy)), int(np.floor(fz))
        h = _hash(i, j, k, mask)
        while True:
            v = slot[h]
            if v < 0:
                if used == cap:
                    keys, sums, cap = _grow(keys), _grow(sums), 2 * cap
                    slot = _rehash(keys, used, 2 * cap)
                    mask = 2 * cap - 1
                    h = _hash(i, j, k, mask)
                    while slot[h] >= 0:
                        h = (h + 1) & mask
                v = used
                slot[h] = v
                keys[v, 0], keys[v, 1], keys[v, 2] = i, j, k
                sums[v, 0], sums[v, 1], sums[v, 2] = x, y, z
                used += 1
                break
            if keys[v, 0] == i and keys[v, 1] == j and keys[v, 2] == k:
                break
            h = (h + 1) & mask
        r = _add_run(points, r, inv, i, j, k, sums[v])
    return sums[:used]


@njit(cache=True, nogil=True)
def _add_run(
    points: np.ndarray, r: int, inv: float, i: int, j: int, k: int, row: np.ndarray
) -> int:
    """Add the points from r on while they fall in voxel (i, j, k) to its ``row`` (13,);
    returns the first row past them. A depth image's neighbouring pixels mostly share a
    voxel: the run's sums stay in locals (the same additions in the same order), not a
    chain of loads and stores through the table per point (2x faster on a depth image)."""
    bx, by, bz = row[0], row[1], row[2]
    s3, s4, s5, s6, s7 = row[3], row[4], row[5], row[6], row[7]
    s8, s9, s10, s11, s12 = row[8], row[9], row[10], row[11], row[12]
    x, y, z = points[r, 0], points[r, 1], points[r, 2]
    while True:
        dx, dy, dz = x - bx, y - by, z - bz
        s3 += dx
        s4 += dy
        s5 += dz
        s6 += dx * dx
        s7 += dy * dy
        s8 += dz * dz
        s9 += dx * dy
        s10 += dx * dz
        s11 += dy * dz
        s12 += 1.0
        r += 1
        if r == points.shape[0]:
            break
        x, y, z = points[r, 0], points[r, 1], points[r, 2]
        # A skipped row (NaN, huge) ends the run too: the caller steps over it.
        fx, fy, fz = x * inv, y * inv, z * inv
        if not (abs(fx) < _MAX_INDEX and abs(fy) < _MAX_INDEX and abs(fz) < _MAX_INDEX):
            break
        if int(np.floor(fx)) != i or int(np.floor(fy)) != j or int(np.floor(fz)) != k:
            break
    row[3], row[4], row[5], row[6], row[7] = s3, s4, s5, s6, s7
    row[8], row[9], row[10], row[11], row[12] = s8, s9, s10, s11, s12
    return r


def voxel_moments(points: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Count, centroid and covariance of the points in each occupied cube of edge ``size`` m.

    points: (N, 3) float, metres, cells aligned at 0; rows with NaN/inf are skipped (an
    organised depth image marks missing pixels so). Returns, in order of each voxel's first
    point: counts (V,) int64, centroids (V, 3) float64 m, covariances (V, 6) float64 m^2 (xx,
    yy, zz, xy, xz, yz, about the centroid, divided by the count). Raises ValueError on a
    wrong shape or a size that is not positive and finite.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"voxel size must be positive and finite, got {size}")
    s = _sums(pts, 1.0 / float(size))
    n = s[:, 12]
    mean_d = s[:, 3:6] / n[:, None]
    second = s[:, 6:12] / n[:, None]
    pairs = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    cov = np.stack(
        [second[:, c] - mean_d[:, a] * mean_d[:, b] for c, (a, b) in enumerate(pairs)], axis=1
    )
    return n.astype(np.int64), s[:, :3] + mean_d, cov


@warmer
def _warm() -> None:
    voxel_moments(np.array([[0.0, 0.0, 0.0], [0.01, 0.0, np.nan]]), 0.05)
