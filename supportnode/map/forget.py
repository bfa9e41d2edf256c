"""Forgetting: voxels beyond the radius, older than max_age, or beyond the voxel cap."""

from __future__ import annotations

import numpy as np

from supportnode.map.state import StoreState


class Forgetting(StoreState):
    """Mixin of `VoxelMap`: the radius, age and cap pass."""

    def _maybe_forget(self, stamp: float, origin: np.ndarray) -> np.ndarray:
        p = self.params
        due = self._last_pass is None or len(self) > p.max_voxels
        if not due and self._last_pass is not None:
            t0, xy0 = self._last_pass
            moved = float(np.hypot(*(origin[:2] - xy0)))
            due = moved >= self.crop_slack or (p.max_age > 0 and stamp - t0 >= self.age_slack)
        if not due:
            return np.zeros((0, 3), np.int64)
        return self._forget(stamp, origin)

    def _forget(self, stamp: float, origin: np.ndarray) -> np.ndarray:
        """Drop voxels beyond the radius, older than max_age, then the oldest beyond the cap."""
        p = self.params
        self._last_pass = (stamp, origin[:2].copy())
        self._stats["forget_passes"] += 1
        live = np.flatnonzero(self._alive)
        centre = (self._keys[live, :2] + 0.5) * self.size
        far = np.hypot(centre[:, 0] - origin[0], centre[:, 1] - origin[1]) > p.radius
        old = (
            (self._last_seen[live] < stamp - p.max_age) & ~far
            if p.max_age > 0
            else np.zeros(len(live), bool)
        )
        self._stats["dropped_radius"] += int(far.sum())
        self._stats["dropped_age"] += int(old.sum())
        drop = [live[far | old]]
        rest = live[~(far | old)]
        if len(rest) > p.max_voxels:
            # Drop to 95 % of the cap, oldest first, so the O(M) selection is not redone on
            # every scan at the cap.
            excess = len(rest) - int(0.95 * p.max_voxels)
            oldest = np.argpartition(self._last_seen[rest], excess - 1)[:excess]
            drop.append(rest[oldest])
            self._stats["dropped_cap"] += excess
        return self._remove(np.concatenate(drop))
