"""What a sensor sees past an occluder, for tests of shadows across tops."""

from __future__ import annotations

import numpy as np


def seen(points: np.ndarray, origin: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N,) bool: the points (N, 3) whose segment to the origin (3,) misses the box [lo, hi]
    (3,) (a slab test), metres."""
    d = origin - points
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - points) / d, (hi - points) / d
    near = np.nanmax(np.minimum(t0, t1), axis=1)
    far = np.nanmin(np.maximum(t0, t1), axis=1)
    return ~((near <= far) & (far > 0) & (near < 1))
