"""The points of a map whose x, y lie in a box, in one pass that gives up past a share.

The node's regional detection crops the map around what a scan changed, unless the crop
would hold most of the map (then a full detection is cheaper). With numpy the test was a
(N, 2) comparison, a reduction and a count over every point, ~4 ms a scan on a 1M-point map,
only to learn, for a moving sensor, that the crop is too large.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True)
def _crop(pts: np.ndarray, lo: np.ndarray, hi: np.ndarray, limit: int) -> np.ndarray:
    out = np.empty(min(pts.shape[0], limit), np.int64)
    m = 0
    for i in range(pts.shape[0]):
        x, y = pts[i, 0], pts[i, 1]
        if x >= lo[0] and x <= hi[0] and y >= lo[1] and y <= hi[1]:
            out[m] = i
            m += 1
            if m == limit:
                return np.full(1, -1, np.int64)  # at the limit: the caller gives up
    return out[:m].copy()


def crop_rows(points: np.ndarray, lo: np.ndarray, hi: np.ndarray, limit: int) -> np.ndarray | None:
    """Rows (ascending) of the ``points`` (N, 3) float, metres, whose x, y lie in the box
    [lo, hi] (2,), bounds included (infinite bounds: open sides); None when ``limit`` or
    more of them do."""
    pts = np.ascontiguousarray(points).reshape(-1, 3)
    if pts.dtype not in (np.float32, np.float64):  # a map's points are float32: no copy
        pts = pts.astype(np.float64)
    box_lo = np.ascontiguousarray(lo, dtype=np.float64).reshape(2)
    box_hi = np.ascontiguousarray(hi, dtype=np.float64).reshape(2)
    if np.isnan(box_lo).any() or np.isnan(box_hi).any():
        raise ValueError("the box must not be NaN (infinite bounds are open sides)")
    if limit <= 0:
        return None
    rows = _crop(pts, box_lo, box_hi, int(limit))
    if len(rows) == 1 and rows[0] < 0:
        return None
    return rows


@warmer
def _warm() -> None:
    for dtype in (np.float32, np.float64):
        crop_rows(np.zeros((2, 3), dtype), np.zeros(2), np.ones(2), 2)
        crop_rows(np.zeros((2, 3), dtype), np.zeros(2), np.ones(2), 1)
