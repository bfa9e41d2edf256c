"""Free-space clearing: a scan's rays remove the evidence of the voxels they pass through."""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from supportnode.map.keys import _BITS_XY, _BITS_Z, _MAGIC, _OFFS, _SHIFTS, pack_keys
from supportnode.map.scan import _plane_fits

_CHUNK = 1 << 15  # ray samples per chunk in VoxelMap._clear (~256 KB per temporary)


class Clearing:
    """Mixin of `VoxelMap`: ray clearing."""

    def _sample_keys(self, u: np.ndarray, t: np.ndarray, origin: np.ndarray) -> np.ndarray:
        """(J, R) packed keys of the samples ``origin + u * t`` of rays with unit directions
        u (3, R) (a row per axis) at distances t (J,) metres: sample j of every ray, in row j.
        A view of scratch memory, overwritten by the next call.

        The samples outnumber the rays ~50:1, so every pass over them counts. Rays of similar
        length go together (the caller ignores the samples past each ray's end), so a row
        is one distance times a row of directions: numpy's fast scalar-times-vector loop, and
        no direction repeated per sample; a row per ray instead (~50 samples) would pay
        numpy's ~100 ns per row of a broadcast many times over. The keys are built axis by
        axis in reused buffers, with no (S, 3) temporaries. Samples lie between the origin
        and in-range hits, so their keys are in range too (those past a ray's end, within
        the reach of the block's longest ray, may not be: garbage then, never used)."""
        size = self.size
        shape = (len(t), u.shape[1])
        m = shape[0] * shape[1]
        fx = self._buffer("sample_x", m, np.float64).reshape(shape)
        buf = self._buffer("sample_y", m, np.float64).reshape(shape)
        # The keys are integers below 2^53 in float64, so exact; converted not by a cast
        # (numpy's float to int64 is a slow scalar loop) but by adding 2^52, which puts the
        # integer in the low mantissa bits, exactly as the cast would give it: x and y,
        # (kx + off) * 2^22 + ky + off < 2^44, end up shifted into place (the exponent bits
        # shift out), z is masked out.
        for a, out in ((0, fx), (1, buf), (2, buf)):  # three axes
            np.multiply(t[:, None], u[a], out=out)
            out += origin[a]
            out /= size
            np.floor(out, out=out)
            if a == 1:
                fx *= float(1 << _BITS_XY)
                fx += buf
                fx += float(_OFFS[0] << _BITS_XY | _OFFS[1]) + _MAGIC
                packed = fx.view(np.uint64)
                packed <<= np.uint64(_SHIFTS[1])
        buf += float(_OFFS[2]) + _MAGIC
        z = buf.view(np.uint64)
        z &= np.uint64((1 << _BITS_Z) - 1)
        packed |= z
        return packed.view(np.int64)

    def _clear(self, cols: list[np.ndarray], origin: np.ndarray) -> np.ndarray:
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
        size = self.size
        pack_keys(np.floor(origin / size).astype(np.int64)[None])  # range check of the origin
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
        # Longest rays first: what follows does not depend on the order of the rays, and rays
        # of similar length then go together in dense (samples, rays) blocks that waste few
        # samples past the rays' ends (~5 %); rays without samples go last and are dropped.
        # (Ray lengths are a few hundred samples at most: 16-bit keys sort in one radix pass.)
        top = int(n.max()) if len(n) else 0
        if top < 1 << 16:
            order = np.argsort((top - n).astype(np.uint16), kind="stable")
        else:
            order = np.argsort(-n, kind="stable")
        order = order[: np.count_nonzero(n)]
        n, d, dist, pts = n[order], d[order], dist[order], pts[order]
        u = d / dist[:, None]
        rows = np.ascontiguousarray(u.T)
        # t as the samples had it: (j + 0.5) * size, j exact in float64.
        t = np.arange(int(n[0]) if len(n) else 0, dtype=np.float64)
        t += 0.5
        t *= size
        # Blocks of about _CHUNK samples, whose temporaries stay in cache (2-3x faster than one
        # pass over all samples, which are ~50 per ray); each block is looked up at once.
        bounds = [0]
        while bounds[-1] < len(n):  # a few blocks per scan
            bounds.append(min(bounds[-1] + max(_CHUNK // int(n[bounds[-1]]), 1), len(n)))
        # Each block only sifts out the samples that may meet a stored voxel (a few %): the
        # probe loop then runs once for all of them (its iterations cost microseconds each).
        # Consecutive samples of one ray often share a voxel, and each (ray, voxel) counts
        # once: per axis the key is monotone along a ray (so is rounding), so a ray cannot
        # come back to a voxel it left; the first sample of each run of equal keys along a
        # ray stands for the run (all of it passes the filters below, or none).
        rays, keys = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        for r0, r1 in pairwise(bounds):
            width = r1 - r0
            packed = self._sample_keys(rows[:, r0:r1], t[: n[r0]], origin).reshape(-1)
            idx = self._hash.maybe_present(packed)
            j, ray = np.divmod(idx, width)
            ray += r0
            key = packed[idx]
            first = (j < n[ray]) & ((j == 0) | (packed[np.maximum(idx - width, 0)] != key))
            rays.append(ray[first])
            keys.append(key[first])
        found, slot = self._hash.find_present(np.concatenate(keys))
        ray = np.concatenate(rays)[found]
        met = self._last_scan[slot] != self._scans  # hit by this scan: seen, not seen through
        ray, slot = ray[met], slot[met]
        if len(slot) == 0:
            return np.zeros((0, 3), np.int64)

        uniq, inv = np.unique(slot, return_inverse=True)
        corner = self._keys[uniq] * size
        mean, _, normal, planar = _plane_fits(
            self._count[uniq], self._sums[uniq], self._outer[uniq], size
        )
        c = (corner + mean)[inv]
        n_ = normal[inv]
        uu, hit = u[ray], pts[ray]
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
        through = np.where(planar[inv], through_planar, through_other)
        # One decrement per voxel and scan, two when several rays agree (a single ray through
        # a voxel may be noise; several are a clear view through it).
        hit_slots, rays_through = np.unique(slot[through], return_counts=True)
        self._evidence[hit_slots] -= np.where(rays_through >= 3, 2, 1).astype(np.int32)
        gone = hit_slots[self._evidence[hit_slots] <= 0]
        self._stats["cleared"] += len(gone)
        return self._remove(gone)
