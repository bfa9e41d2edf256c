"""Rotating (and translating) a cloud in one compiled pass.

``geometry.transform.transform_points`` stays numpy (the client imports it without numba):
nine column multiply-adds, each a pass over the cloud. Aligning a 640 x 480 depth image to
gravity took ~2 ms that way; one pass that reads each point once takes a third of that. The
arithmetic is the same, operation for operation: the same values.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True)
def _transform(p: np.ndarray, r: np.ndarray, t: np.ndarray, out: np.ndarray) -> None:
    for n in range(p.shape[0]):
        x, y, z = p[n, 0], p[n, 1], p[n, 2]
        for i in range(3):
            # As transform_points: ((x r0 + y r1) + z r2) + t, no fused multiply-add.
            out[n, i] = x * r[i, 0] + y * r[i, 1] + z * r[i, 2] + t[i]


def transform_points_fast(
    points: np.ndarray, rotation: np.ndarray, translation: np.ndarray | None = None
) -> np.ndarray:
    """``transform_points(points, rotation, translation)``, the same values: (N, 3) float
    metres -> (N, 3) float64; rotation (3, 3), translation (3,) or None."""
    p = np.asarray(points).reshape(-1, 3)
    if p.dtype not in (np.float32, np.float64):
        p = p.astype(np.float64)
    r = np.ascontiguousarray(rotation, dtype=np.float64).reshape(3, 3)
    t = np.zeros(3) if translation is None else np.asarray(translation, np.float64).reshape(3)
    out = np.empty((len(p), 3))
    _transform(p, r, t, out)
    return out


@warmer
def _warm() -> None:
    for dtype in (np.float32, np.float64):
        transform_points_fast(np.zeros((1, 3), dtype), np.eye(3))
