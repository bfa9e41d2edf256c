"""Covariances of k-nearest-neighbour sets: one loop over each query's neighbours.

k-NN normals need the covariance of every query's k neighbours; numpy formed them through a
sparse (queries x points) selection matrix times the points' nine moments. Here the moments
are summed as the neighbours are read, with nothing built in between.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True)
def _covariances(c: np.ndarray, idx: np.ndarray) -> np.ndarray:
    rows, k = idx.shape
    out = np.empty((6, rows))
    inv = 1.0 / k
    for r in range(rows):
        sx = sy = sz = xx = yy = zz = xy = xz = yz = 0.0
        for q in range(k):
            j = idx[r, q]
            x, y, z = c[j, 0], c[j, 1], c[j, 2]
            sx += x
            sy += y
            sz += z
            xx += x * x
            yy += y * y
            zz += z * z
            xy += x * y
            xz += x * z
            yz += y * z
        mx, my, mz = sx * inv, sy * inv, sz * inv
        out[0, r] = xx * inv - mx * mx
        out[1, r] = yy * inv - my * my
        out[2, r] = zz * inv - mz * mz
        out[3, r] = xy * inv - mx * my
        out[4, r] = xz * inv - mx * mz
        out[5, r] = yz * inv - my * mz
    return out


def neighbourhood_covariances(points: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Population covariance of each row's neighbours: (6, R) float64, m^2, entries xx, yy,
    zz, xy, xz, yz (``voxels.OUTER_INDEX`` order, for ``linalg.sym3_eigen_entries``).

    points: (N, 3) float64 metres, finite, best centred near 0 (the sums of squares cancel);
    idx: (R, k) int, k >= 1, neighbour indices into points. Raises ValueError on shapes,
    indices out of range or non-finite points.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    ix = np.ascontiguousarray(idx, dtype=np.int64)
    if ix.ndim != 2 or (ix.shape[0] and ix.shape[1] < 1):
        raise ValueError(f"idx must have shape (R, k) with k >= 1, got {ix.shape}")
    if ix.size and (ix.min() < 0 or ix.max() >= len(pts)):
        raise ValueError(f"neighbour indices must lie in [0, {len(pts)})")
    if not np.isfinite(pts).all():
        raise ValueError("points must be finite")
    return _covariances(pts, ix)


@warmer
def _warm() -> None:
    neighbourhood_covariances(np.eye(3), np.array([[0, 1, 2]]))
