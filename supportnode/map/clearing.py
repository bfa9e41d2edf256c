"""Free-space clearing: a scan's rays remove the evidence of the voxels they pass through.

The rays' march (`kernels.rays`, compiled, without the interpreter lock) runs on a helper
thread while the scan's voxels merge: it reads the key table as it was before the scan (the
merge inserts its new keys only once the march is done), and the voxels this scan hit are
dropped from its pairs afterwards, so the map equals a march after the merge. The node's
receiving thread gains the march's time (~3.5 ms of a 131k-point scan) when a second core is
free, and loses a thread hand-off when not.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from supportnode.kernels.rays import ray_voxels
from supportnode.map.keys import _OFFS, _SHIFTS, pack_keys
from supportnode.map.scan import _plane_fits
from supportnode.map.state import StoreState

_SHIFT_ARR = np.array(_SHIFTS, np.int64)

_EXECUTOR: tuple[int, ThreadPoolExecutor] | None = None
_EXECUTOR_LOCK = threading.Lock()


def _executor() -> ThreadPoolExecutor:
    """One marching thread per process (a forked child makes its own: threads do not fork)."""
    global _EXECUTOR
    with _EXECUTOR_LOCK:
        if _EXECUTOR is None or _EXECUTOR[0] != os.getpid():
            pool = ThreadPoolExecutor(1, thread_name_prefix="supportnode-rays")
            _EXECUTOR = (os.getpid(), pool)
        return _EXECUTOR[1]


class March:
    """A scan's rays (unit directions ``u`` (R, 3), hits ``pts`` (R, 3), metres) and their
    march in flight; `pairs` waits for it once."""

    def __init__(self, u: np.ndarray, pts: np.ndarray, future: Future) -> None:
        self.u, self.pts = u, pts
        self._future: Future | None = future
        self._pairs: tuple[np.ndarray, np.ndarray] | None = None

    def pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(ray, slot) pairs, (M,) int64 each, of the stored voxels the rays pass through."""
        if self._pairs is None:
            assert self._future is not None
            self._pairs, self._future = self._future.result(), None
        return self._pairs


class Clearing(StoreState):
    """Mixin of `VoxelMap`: ray clearing."""

    def _begin_clear(self, cols: list[np.ndarray], origin: np.ndarray) -> March:
        """Sample the scan's clearing rays and start their march (see the module docstring);
        call before `_merge`, and finish with `_clear`."""
        size = self.size
        pack_keys(np.floor(origin / size).astype(np.int64)[None])  # range check of the origin
        u, n, pts = self._sample_rays(cols, origin)
        table = self._hash.table
        scan = self._scans
        future = _executor().submit(
            ray_voxels, origin, u, n, size, table, _OFFS, _SHIFT_ARR, self._last_scan, scan
        )
        return March(u, pts, future)

    def _clear(self, march: March, origin: np.ndarray) -> np.ndarray:
        """Free-space clearing along the scan's rays; returns the removed (R, 3) keys.

        Rays (a random subset of ``clear_rays``) are sampled every voxel length from the origin
        up to two voxels before their hit. A stored voxel met on the way and not hit by this
        scan loses evidence if the ray really went through what it holds:
        - planar voxel (>= 4 points spread in two directions, thinnest spread < 1/4 of the
          next): the ray crosses the voxel's plane inside the voxel (half a voxel of margin)
          and ends at least ``clear_tolerance`` behind that plane. A ray grazing a floor ends
          on the same plane, so distant floor seen at grazing angles survives;
        - other voxels (few points, or a line of them: one lidar ring): the ray ends at least
          ``clear_tolerance`` above or below the voxel's centroid, so a ray that ends on the
          same horizontal surface never clears it (z is up in the map frame).
        Evidence drops by one per scan, by two when three or more rays agree.
        """
        ray, slot = march.pairs()
        # The voxels this scan hit are seen, not seen through (the march ran on the table
        # from before the merge).
        seen = self._last_scan[slot] == self._scans
        if seen.any():
            ray, slot = ray[~seen], slot[~seen]
        u, pts = march.u, march.pts
        if len(slot) == 0:
            return np.zeros((0, 3), np.int64)
        through = self._through(slot, origin, u[ray], pts[ray])
        # One decrement per voxel and scan, two when several rays agree (a single ray through
        # a voxel may be noise; several are a clear view through it).
        hit_slots, rays_through = np.unique(slot[through], return_counts=True)
        self._evidence[hit_slots] -= np.where(rays_through >= 3, 2, 1).astype(np.int32)
        gone = hit_slots[self._evidence[hit_slots] <= 0]
        self._stats["cleared"] += len(gone)
        return self._remove(gone)

    def _sample_rays(
        self, cols: list[np.ndarray], origin: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The clearing rays of a scan (x, y, z columns (N,), map frame) from ``origin`` (3,):
        unit directions (R, 3), samples per ray (R,) and the rays' hits (R, 3), metres."""
        size = self.size
        if len(cols[0]) > self.clear_rays:
            pick = self._rng.choice(len(cols[0]), self.clear_rays, replace=False)
            pts = np.stack([c[pick] for c in cols], axis=1)
        else:
            pts = np.stack(cols, axis=1)
        d = pts - origin
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        # Nothing is kept beyond the radius: marching further (a stray return kilometres away)
        # would only cost time.
        rng_ = np.minimum(dist, self.params.radius + 2 * size)
        # One sample per voxel length: a ray may skip a corner it clips, which only delays
        # clearing there; half steps would double the cost for little. Rays of three voxels
        # or less get none.
        step = size
        n = np.maximum(np.floor((rng_ - 2 * size) / step).astype(np.int64), 0)
        n = np.where(dist > 3 * size, n, 0)
        # Rays without samples are dropped (a zero-length one has no direction).
        keep = np.flatnonzero(n)
        n, d, dist, pts = n[keep], d[keep], dist[keep], pts[keep]
        return d / dist[:, None], n, pts

    def _through(
        self, slot: np.ndarray, origin: np.ndarray, uu: np.ndarray, hit: np.ndarray
    ) -> np.ndarray:
        """(P,) bool: did each (ray, voxel) pair pass through what the voxel at ``slot`` (P,)
        holds (see _clear)? uu (P, 3): the ray's direction; hit (P, 3): where it ended, m."""
        size = self.size
        uniq, inv = np.unique(slot, return_inverse=True)
        corner = self._keys[uniq] * size
        mean, _, normal, planar = _plane_fits(
            self._count[uniq], self._sums[uniq], self._outer[uniq], size
        )
        c = (corner + mean)[inv]
        n_ = normal[inv]
        tol = self.clear_tolerance

        # Planar: crossing point of the ray with the voxel's plane, inside the voxel (+ half a
        # voxel of margin: its plane is fitted to few points), and the hit behind the plane by
        # at least tol.
        denom = np.einsum("ij,ij->i", uu, n_)
        safe = np.where(np.abs(denom) > 1e-9, denom, 1e-9)
        tc = np.einsum("ij,ij->i", c - origin, n_) / safe
        cross = origin + uu * tc[:, None]
        rel = cross - corner[inv]
        inside = np.all((rel > -0.5 * size) & (rel < 1.5 * size), axis=1) & (tc > 0)
        o_side = np.einsum("ij,ij->i", origin - c, n_)
        h_side = np.einsum("ij,ij->i", hit - c, n_)
        behind = (np.sign(o_side) != np.sign(h_side)) & (np.abs(h_side) >= tol)
        through_planar = inside & behind & (np.abs(denom) > 1e-9)

        # Sparse or linear (a lidar ring leaves a line of points): the ray went through the
        # voxel (it was sampled in it) and ends clearly above or below it.
        through_other = np.abs(hit[:, 2] - c[:, 2]) >= tol
        return np.where(planar[inv], through_planar, through_other)
