"""Neighbourhood offsets shared by compiled kernels and numpy code. No numba here: importing
the offsets loads no kernel (`runtime.warm` loads those of every imported kernel module)."""

from __future__ import annotations

import numpy as np

__all__ = ["FORWARD_26"]

# The 13 forward offsets of the 26-neighbourhood (dx, dy, dz) > (0, 0, 0): each adjacent
# pair once (`cellgraph`'s cell pairs, the objects' voxel linking `geometry.objects.neighbours`).
FORWARD_26 = np.array(
    [
        (dx, dy, dz)
        for dx in (-1, 0, 1)
        for dy in (-1, 0, 1)
        for dz in (-1, 0, 1)
        if (dx, dy, dz) > (0, 0, 0)
    ],
    dtype=np.int64,
)
