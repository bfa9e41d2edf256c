"""What holds what: the object each object stands on (a box on a box), from their boxes."""

from __future__ import annotations

import numpy as np

# A top and a bottom this close in height touch (Kinect noise at 1.5 m, plus the table band
# the convex segmentation leaves out under an object).
CONTACT = 0.02
# An object resting on another covers at least this share of its own footprint box with the
# other's (a box leaning beside a taller one touches its side, not its top).
OVERLAP = 0.3


def supported_by(
    bbox_min: np.ndarray, bbox_max: np.ndarray, base: np.ndarray, tol: float = CONTACT
) -> np.ndarray:
    """(C,) int64 the cluster each cluster stands on, -1 when on its surface (or nothing).

    bbox_min, bbox_max: (C, 3) float64 axis-aligned boxes, metres, z up; base: (C,) float64
    height of the surface under each cluster (NaN: none). Cluster i stands on j when i's
    bottom is more than ``tol`` above its surface, j's top is within ``tol`` of i's bottom,
    and their footprint boxes overlap by >= OVERLAP of i's; among several, the highest top.
    """
    lo = np.asarray(bbox_min, np.float64).reshape(-1, 3)
    hi = np.asarray(bbox_max, np.float64).reshape(-1, 3)
    n = len(lo)
    out = np.full(n, -1, np.int64)
    if n < 2:
        return out
    bottom, top = lo[:, 2], hi[:, 2]
    raised = ~(bottom - np.asarray(base, np.float64) <= tol)  # NaN base: nothing under it
    w = np.clip(
        np.minimum(hi[:, None, :2], hi[None, :, :2]) - np.maximum(lo[:, None, :2], lo[None, :, :2]),
        0,
        None,
    )
    inter = w[..., 0] * w[..., 1]
    own = np.prod(np.maximum(hi[:, :2] - lo[:, :2], 1e-9), axis=1)
    ok = (inter >= OVERLAP * own[:, None]) & (np.abs(top[None, :] - bottom[:, None]) <= tol)
    ok &= raised[:, None] & (top[None, :] < top[:, None])
    np.fill_diagonal(ok, False)
    score = np.where(ok, top[None, :], -np.inf)
    best = score.argmax(axis=1)
    has = ok.any(axis=1)
    out[has] = best[has]
    return out
