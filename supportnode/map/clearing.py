"""Free-space clearing: a scan's rays remove the evidence of the voxels they pass through.

The rays' march (`kernels.rays`, compiled) runs on the map after the scan's merge, whose
voxels it skips (seen, not seen through). The node runs it once its detection has taken the
map's points (`VoxelMap.settle`): beside the detection, on the receiving thread.
"""

from __future__ import annotations

import numpy as np

from supportnode.kernels.rays import ray_voxels
from supportnode.map.keys import _OFFS, _SHIFTS
from supportnode.map.scan import _plane_fits
from supportnode.map.state import StoreState

_SHIFT_ARR = np.array(_SHIFTS, np.int64)


class Clearing(StoreState):
    """Mixin of `VoxelMap`: ray clearing."""

    def _clear(self, cols: list[np.ndarray], origin: np.ndarray) -> np.ndarray:
        """Free-space clearing along the rays of the scan just merged (its x, y, z columns
        (N,), map frame, from ``origin`` (3,)); returns the removed (R, 3) keys.

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
        u, n, pts = self._sample_rays(cols, origin)
        ray, slot = ray_voxels(
            origin,
            u,
            n,
            self.size,
            self._hash.table,
            _OFFS,
            _SHIFT_ARR,
            self._last_scan,
            self._scans,
        )
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
