"""Counts of unit normals near candidate axes (n and -n one axis): the density of directions."""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True)
def _support(axes: np.ndarray, normals: np.ndarray, cos_min: float) -> np.ndarray:
    out = np.zeros(axes.shape[0], np.int64)
    for a in range(axes.shape[0]):
        ax, ay, az = axes[a, 0], axes[a, 1], axes[a, 2]
        c = 0
        for i in range(normals.shape[0]):
            if abs(ax * normals[i, 0] + ay * normals[i, 1] + az * normals[i, 2]) >= cos_min:
                c += 1
        out[a] = c
    return out


def axis_support(axes: np.ndarray, normals: np.ndarray, cos_min: float) -> np.ndarray:
    """For each axis, how many normals lie within the cone |n . a| >= ``cos_min``.

    axes: (A, 3) float unit; normals: (M, 3) float unit, sign ignored. Returns (A,) int64.
    Raises ValueError on wrong shapes or non-finite values.
    """
    a = np.ascontiguousarray(axes, dtype=np.float64)
    n = np.ascontiguousarray(normals, dtype=np.float64)
    for name, arr in (("axes", a), ("normals", n)):
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise ValueError(f"{name} must have shape (K, 3), got {arr.shape}")
        if not np.isfinite(arr).all():
            raise ValueError(f"{name} must be finite")
    return _support(a, n, float(cos_min))


@warmer
def _warm() -> None:
    axis_support(np.eye(3), np.eye(3), 0.9)
