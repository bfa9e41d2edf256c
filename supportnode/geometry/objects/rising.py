"""The footprint of what rises from a level (`layers`): the x, y box of its points and their
smallest turned box, and which points of the level lie outside it.

The level's face shows beyond what stands on it when enough of its points lie outside that
footprint. Its axis-aligned box alone misses a box turned on the box under it (a few degrees
put the upper box's corners over the lower one's rim: all of the rim lies inside the upper
box's axis-aligned box); its convex hull would see every bay of a row of things standing
behind a keyboard as face shown beyond them (the TUM desk). Both boxes hold all of its
points; a point outside either is outside what rises.

Points xy (K, 2) float64 metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.geometry.objects.hull import _oriented_rect
from supportnode.kernels.hull import footprint_hulls


@dataclass(frozen=True)
class Footprint:
    """Two boxes around what rises, each grown by ``margin`` metres: lo, hi (2,) the x, y
    box; centre (2,), half (2,) the half length and width of the turned box, whose length
    axis is ``axis`` (2,), a unit vector."""

    lo: np.ndarray
    hi: np.ndarray
    centre: np.ndarray
    axis: np.ndarray
    half: np.ndarray

    def inside(self, xy: np.ndarray) -> np.ndarray:
        """(Q,) bool: which of xy (Q, 2) lie inside both boxes."""
        d = xy - self.centre
        u = np.abs(d @ self.axis)
        v = np.abs(d[:, 1] * self.axis[0] - d[:, 0] * self.axis[1])
        in_box = np.all((xy >= self.lo) & (xy <= self.hi), axis=1)
        return in_box & (u <= self.half[0]) & (v <= self.half[1])


def footprint(xy: np.ndarray, margin: float, box: tuple | None = None) -> Footprint:
    """The `Footprint` of the points xy (K >= 1, 2), grown by ``margin`` m; box: their x, y
    box (lo, hi) when the caller has it. (The levels screened in bulk: `kernels.turned`.)"""
    lo, hi = box if box is not None else (xy.min(axis=0), xy.max(axis=0))
    rows, _ = footprint_hulls(xy, np.zeros(1, np.int64), np.full(1, len(xy), np.int64))
    centre, length, width, yaw = _oriented_rect(xy[rows])
    return Footprint(
        lo - margin,
        hi + margin,
        centre,
        np.array([np.cos(yaw), np.sin(yaw)]),
        np.array([length / 2 + margin, width / 2 + margin]),
    )
