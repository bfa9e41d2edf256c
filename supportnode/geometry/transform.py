"""Rigid transforms of point arrays without BLAS.

``points @ rotation.T`` hands an (N, 3) x (3, 3) product to the multithreaded BLAS, whose
threads wait on each other when the cores are busy: on this 2-core machine under load it took
20-65 ms for 131k points, against 1.5 ms for the nine column multiply-adds below (0.5 ms both
ways when idle). A robot's computer is never idle, so hot paths use this.
"""

from __future__ import annotations

import numpy as np

__all__ = ["transform_points"]


def transform_points(
    points: np.ndarray, rotation: np.ndarray, translation: np.ndarray | None = None
) -> np.ndarray:
    """``points @ rotation.T + translation``: (N, 3) -> (N, 3) float64.

    points: (N, 3) any float dtype; rotation: (3, 3); translation: (3,) or None.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    r = np.asarray(rotation, dtype=np.float64)
    out = np.empty_like(p)
    for i in range(3):  # three output columns
        col = out[:, i]
        np.multiply(p[:, 0], r[i, 0], out=col)
        col += p[:, 1] * r[i, 1]
        col += p[:, 2] * r[i, 2]
        if translation is not None:
            col += float(translation[i])
    return out
