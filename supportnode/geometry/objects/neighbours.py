"""The voxel neighbourhood both segmentations link over."""

from __future__ import annotations

import numpy as np

__all__ = ["FORWARD_26"]

# The 13 "forward" offsets of the 26-neighbourhood (dx, dy, dz) > (0, 0, 0): each undirected
# pair of adjacent voxels is tested once. (13, 3) int64.
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
