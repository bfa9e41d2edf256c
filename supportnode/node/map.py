"""Incremental voxel map: posed scans merged into per-voxel moments, aged, cropped, ray-cleared.

State lives in the map frame (z up, metres). Every occupied voxel (edge ``voxel_size``) keeps the
moments of the points merged into it relative to its own corner, exactly as
:func:`supportnode.geometry.voxels.voxelize` computes them, so merging scan after scan is exact
(merging two scans equals voxelizing their union) and stays precise far from the origin.

Cost per scan depends on the scan, not on the map size:

- voxels live in slots of a growable store with a free list (removal frees a slot, insertion
  reuses one; the store only doubles, it is never compacted);
- keys are found through an open-addressing hash table held in numpy arrays (linear probing,
  vectorised over all queries of a scan, one loop iteration per probe step, not per voxel);
- forgetting by radius and age is a vectorised pass over the store, run only when the sensor
  has moved ``crop_slack`` metres or ``age_slack`` seconds went by since the last pass (voxels may
  overstay by that much), or when the voxel cap is exceeded.

Pure: numpy in, numpy out; no sockets, files or printing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.errors import InputError
from supportnode.geometry.linalg import sym3_eigen
from supportnode.geometry.transform import transform_points
from supportnode.geometry.voxels import OUTER_INDEX, VoxelGrid, voxelize
from supportnode.params import MapParams

# Keys are packed into one non-negative int64: 22 bits for x and y, 19 for z, each around an
# offset of half its range: |x|, |y| < 2^21 voxels (+-105 km at 5 cm), |z| < 2^18 (+-13 km).
_BITS_XY, _BITS_Z = 22, 19
_OFFS = np.array([1 << (_BITS_XY - 1), 1 << (_BITS_XY - 1), 1 << (_BITS_Z - 1)], np.int64)
_SHIFTS = (_BITS_XY + _BITS_Z, _BITS_Z, 0)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: scatters spatially close keys
_EMPTY, _TOMB = -1, -2
REPRESENTATIONS = ("recent", "centroid")


def pack_keys(keys: np.ndarray) -> np.ndarray:
    """(N, 3) int64 voxel keys -> (N,) non-negative int64; raises InputError out of range."""
    k = np.asarray(keys, dtype=np.int64).reshape(-1, 3) + _OFFS
    if k.size and ((k < 0).any() or (k >= 2 * _OFFS).any()):
        raise InputError(
            "points too far from the map origin for this voxel size "
            f"(|key| must stay below 2^{_BITS_XY - 1} in x, y and 2^{_BITS_Z - 1} in z)"
        )
    return (k[:, 0] << _SHIFTS[0]) | (k[:, 1] << _SHIFTS[1]) | k[:, 2]


def unpack_keys(packed: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pack_keys`: (N,) int64 -> (N, 3) int64."""
    p = np.asarray(packed, dtype=np.int64)
    cols = [(p >> _SHIFTS[a]) & ((2 * _OFFS[a]) - 1) for a in range(3)]
    return np.stack(cols, axis=1) - _OFFS


class KeyHash:
    """Packed voxel key -> slot, open addressing with linear probing in numpy arrays.

    Every operation is vectorised over its queries; the Python loop runs once per probe step
    (a handful at load <= 1/2). Deleted entries become tombstones; the table is rebuilt (O(size),
    amortised over at least as many insertions) when entries plus tombstones pass half of it.
    """

    def __init__(self, capacity: int = 1 << 12) -> None:
        self._alloc(max(1 << 4, 1 << int(np.ceil(np.log2(capacity)))))
        self.size = 0

    def _alloc(self, capacity: int) -> None:
        self.keys = np.full(capacity, _EMPTY, dtype=np.int64)
        self.vals = np.zeros(capacity, dtype=np.int64)
        self.tombs = 0
        self._shift = np.uint64(64 - int(np.log2(capacity)))

    @property
    def capacity(self) -> int:
        return len(self.keys)

    def _home(self, q: np.ndarray) -> np.ndarray:
        # Views, not copies: packed keys are non-negative and the shifted hash fits in int64.
        h = np.ascontiguousarray(q, dtype=np.int64).view(np.uint64) * _GOLDEN
        h >>= self._shift
        return h.view(np.int64)

    def _locate(self, q: np.ndarray) -> np.ndarray:
        """Table position of each (Q,) packed key, -1 where absent."""
        out = np.full(len(q), -1, dtype=np.int64)
        pos = self._home(q)
        # First probe on everything; most queries (ray samples in free space) stop here.
        k = self.keys[pos]
        hit = k == q
        out[hit] = pos[hit]
        idx = np.flatnonzero(~hit & (k != _EMPTY))
        mask = self.capacity - 1
        pos = (pos[idx] + 1) & mask
        while idx.size:
            k = self.keys[pos]
            hit = k == q[idx]
            out[idx[hit]] = pos[hit]
            go_on = ~hit & (k != _EMPTY)  # tombstones do not end a probe chain
            idx, pos = idx[go_on], (pos[go_on] + 1) & mask
        return out

    def find(self, q: np.ndarray) -> np.ndarray:
        """Slot of each (Q,) packed key, -1 where absent."""
        pos = self._locate(q)
        return np.where(pos >= 0, self.vals[np.maximum(pos, 0)], -1)

    def insert(self, q: np.ndarray, vals: np.ndarray) -> None:
        """Insert (Q,) distinct packed keys that are not in the table, with their slots."""
        if len(q) == 0:
            return
        if 2 * (self.size + self.tombs + len(q)) > self.capacity:
            self._rebuild(self.size + len(q))
        idx = np.arange(len(q))
        pos = self._home(q)
        mask = self.capacity - 1
        while idx.size:
            k = self.keys[pos]
            free = k < 0
            ci, cp = idx[free], pos[free]
            # Several queries may claim one free position: one write wins, read back to see which.
            self.keys[cp] = q[ci]
            won = self.keys[cp] == q[ci]
            self.vals[cp[won]] = vals[ci[won]]
            self.tombs -= int((k[free][won] == _TOMB).sum())
            idx = np.concatenate([idx[~free], ci[~won]])
            pos = (np.concatenate([pos[~free], cp[~won]]) + 1) & mask
        self.size += len(q)

    def delete(self, q: np.ndarray) -> None:
        """Remove (Q,) distinct packed keys that are in the table."""
        pos = self._locate(q)
        pos = pos[pos >= 0]
        self.keys[pos] = _TOMB
        self.size -= len(pos)
        self.tombs += len(pos)

    def _rebuild(self, live: int) -> None:
        keep = self.keys >= 0
        keys, vals = self.keys[keep], self.vals[keep]
        self._alloc(max(1 << 4, 1 << int(np.ceil(np.log2(4 * max(live, 1))))))
        self.size = 0
        self.insert(keys, vals)


@dataclass
class Touched:
    """What one :meth:`VoxelMap.integrate` changed.

    keys: (T, 3) int64 voxels hit by the scan (all still in the map when returned).
    removed: (R, 3) int64 voxels removed by this call (free-space clearing and forgetting).
    lo, hi: (3,) float64 bounding box of the scan's points in the map frame, metres
        (lo > hi componentwise for an empty scan).
    """

    keys: np.ndarray
    removed: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


class VoxelMap:
    """Incremental voxel map of posed scans (see the module docstring).

    params: ``MapParams`` (radius, max_age, max_voxels, voxel_size, clear_free_space).
    representation: points handed to detection by :meth:`points`: ``"recent"`` keeps the
        ``keep_points`` newest raw points of every voxel (float32 relative to its corner);
        ``"centroid"`` gives one point per voxel, the mean of everything merged into it.
    max_evidence: a voxel's evidence grows by one per scan that hits it, up to this cap, and
        drops by one per scan whose rays pass through it (two when three or more rays do); it
        is removed at zero. The cap bounds how many see-through scans an object that stood
        still for long needs to vanish (2 to 4).
    clear_rays: rays used for clearing per scan (a random subset of the scan's; a different
        one each scan, so repeated scans cover the scene).
    clear_tolerance: a ray clears a voxel only if it ends at least this far beyond the
        voxel's surface (see :meth:`_clear`), metres; None: one voxel edge.
    crop_slack, age_slack: the radius and age pass runs once the sensor moved crop_slack metres
        or age_slack seconds went by since the last pass; None: 5 % of radius, 10 % of max_age.
    seed: of the ray subsampling.
    """

    def __init__(
        self,
        params: MapParams | None = None,
        *,
        representation: str = "recent",
        keep_points: int = 4,
        max_evidence: int = 4,
        clear_rays: int = 8192,
        clear_tolerance: float | None = None,
        crop_slack: float | None = None,
        age_slack: float | None = None,
        seed: int = 0,
    ) -> None:
        self.params = params or MapParams()
        if representation not in REPRESENTATIONS:
            raise InputError(f"representation must be one of {REPRESENTATIONS}")
        self.representation = representation
        self.keep_points = int(keep_points) if representation == "recent" else 0
        self.max_evidence = int(max_evidence)
        self.clear_rays = int(clear_rays)
        self.size = float(self.params.voxel_size)
        self.clear_tolerance = self.size if clear_tolerance is None else float(clear_tolerance)
        self.crop_slack = 0.05 * self.params.radius if crop_slack is None else float(crop_slack)
        self.age_slack = 0.1 * self.params.max_age if age_slack is None else float(age_slack)
        self._rng = np.random.default_rng(seed)
        self._hash = KeyHash()
        self._alloc_store(1 << 12)
        self._free = np.arange(self._capacity - 1, -1, -1, dtype=np.int64)  # stack, pop at end
        self._nfree = self._capacity
        self._scans = 0
        self._last_pass: tuple[float, np.ndarray] | None = None
        self._stats = dict.fromkeys(
            (
                "scans",
                "points_merged",
                "points_invalid",
                "dropped_radius",
                "dropped_age",
                "dropped_cap",
                "cleared",
                "forget_passes",
            ),
            0,
        )

    # ----------------------------------------------------------------- store

    def _alloc_store(self, capacity: int) -> None:
        self._capacity = capacity
        self._keys = np.zeros((capacity, 3), np.int64)
        self._packed = np.zeros(capacity, np.int64)
        self._alive = np.zeros(capacity, bool)
        self._count = np.zeros(capacity, np.int64)
        self._sums = np.zeros((capacity, 3))
        self._outer = np.zeros((capacity, 6))
        self._last_seen = np.zeros(capacity)
        self._last_scan = np.full(capacity, -1, np.int64)
        self._evidence = np.zeros(capacity, np.int32)
        k = max(self.keep_points, 1)
        self._raw = np.zeros((capacity, k, 3), np.float32)
        self._raw_n = np.zeros(capacity, np.int32)
        self._raw_head = np.zeros(capacity, np.int32)

    def _grow(self, need: int) -> None:
        """Double the store until ``need`` more slots are free (amortised O(1) per voxel)."""
        old = self._capacity
        new = old
        while new - old + self._nfree < need:
            new *= 2
        saved = {
            name: getattr(self, name)
            for name in (
                "_keys",
                "_packed",
                "_alive",
                "_count",
                "_sums",
                "_outer",
                "_last_seen",
                "_last_scan",
                "_evidence",
                "_raw",
                "_raw_n",
                "_raw_head",
            )
        }
        self._alloc_store(new)
        for name, arr in saved.items():
            getattr(self, name)[:old] = arr
        added = np.arange(new - 1, old - 1, -1, dtype=np.int64)
        self._free = np.concatenate([self._free[: self._nfree], added])
        self._nfree = len(self._free)

    def _take(self, n: int) -> np.ndarray:
        if n > self._nfree:
            self._grow(n)
        self._nfree -= n
        return self._free[self._nfree : self._nfree + n].copy()

    def _remove(self, slots: np.ndarray) -> np.ndarray:
        """Free (R,) distinct live slots; returns their (R, 3) keys."""
        keys = self._keys[slots].copy()
        self._hash.delete(self._packed[slots])
        self._alive[slots] = False
        self._raw_n[slots] = 0
        self._raw_head[slots] = 0
        end = self._nfree + len(slots)
        if end > len(self._free):
            self._free = np.concatenate([self._free[: self._nfree], slots])
        else:
            self._free[self._nfree : end] = slots
        self._nfree = end
        return keys

    # ----------------------------------------------------------------- public

    def __len__(self) -> int:
        return self._hash.size

    def integrate(
        self,
        points: np.ndarray,
        pose: np.ndarray,
        stamp: float,
        *,
        in_map_frame: bool = False,
    ) -> Touched:
        """Merge one scan.

        points: (N, 3) float, metres, in the sensor frame (or already in the map frame with
            ``in_map_frame=True``). Non-finite points (a driver's misses) are skipped.
        pose: (4, 4) sensor-to-map transform; its translation is the ray origin for clearing
            and the centre of the radius crop.
        stamp: seconds, non-decreasing across calls (ages are measured from the newest stamp).
        Returns the voxels hit and removed, and the scan's bounding box (:class:`Touched`).
        """
        pts = np.asarray(points, dtype=np.float64)
        pose = np.asarray(pose, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(f"points must be an (N, 3) array, got shape {pts.shape}")
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise InputError("pose must be a finite (4, 4) sensor-to-map transform")
        # Column by column: numpy reduces the short axis of an (N, 3) array 5-20x slower.
        finite = np.isfinite(pts[:, 0] + pts[:, 1] + pts[:, 2])
        if not finite.all():
            self._stats["points_invalid"] += int((~finite).sum())
            pts = pts[finite]
        if not in_map_frame:
            pts = transform_points(pts, pose[:3, :3], pose[:3, 3])
        origin = pose[:3, 3].copy()
        self._scans += 1
        self._stats["scans"] += 1
        self._stats["points_merged"] += len(pts)

        slots = self._merge(pts, float(stamp))
        removed = []
        if self.params.clear_free_space and len(pts):
            removed.append(self._clear(pts, origin))
        removed.append(self._maybe_forget(float(stamp), origin))
        hit = slots[self._alive[slots]]
        lo = np.array([pts[:, a].min() for a in range(3)]) if len(pts) else np.full(3, np.inf)
        hi = np.array([pts[:, a].max() for a in range(3)]) if len(pts) else np.full(3, -np.inf)
        return Touched(self._keys[hit].copy(), np.concatenate(removed), lo, hi)

    def points(self, keys: np.ndarray | None = None) -> np.ndarray:
        """Representative points for detection: (P, 3) float64, map frame, metres.

        keys: (Q, 3) int64 voxels to take them from (e.g. ``Touched.keys``; absent ones are
        skipped), None for the whole map. "recent": up to ``keep_points`` raw points per voxel;
        "centroid": one point per voxel.
        """
        return self._points_of(self._slots(keys))

    def centroids(self, max_points: int | None = None) -> np.ndarray:
        """(V, 3) float64 mean of each voxel's points, map frame, metres; at most
        ``max_points`` of them (every k-th voxel in store order) when given."""
        slots = np.flatnonzero(self._alive)
        if max_points is not None and len(slots) > max_points:
            slots = slots[:: -(-len(slots) // max_points)]
        return self._keys[slots] * self.size + self._sums[slots] / self._count[slots, None]

    def points_in_box(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        rotation: np.ndarray | None = None,
        max_share: float = 1.0,
    ) -> np.ndarray | None:
        """:meth:`points` of the voxels that may hold points whose x, y after ``rotation``
        (3, 3), map frame -> another frame (e.g. gravity-aligned), lie in the box [lo, hi] (2,)
        of that frame: a superset, map frame; the caller applies the exact test. None when
        those voxels are ``max_share`` or more of the map. Costs one pass over the voxel keys,
        not over the map's points."""
        live = np.flatnonzero(self._alive)
        centre = (self._keys[live] + 0.5) * self.size
        if rotation is not None:
            centre = transform_points(centre, rotation)
        pad = self.size * np.sqrt(3.0) / 2.0  # a point lies within this of its voxel's centre
        xy = centre[:, :2]
        sel = np.all((xy >= np.asarray(lo) - pad) & (xy <= np.asarray(hi) + pad), axis=1)
        n = int(sel.sum())
        if n >= max_share * len(live):
            return None
        return self._points_of(live[sel])

    def _points_of(self, slots: np.ndarray) -> np.ndarray:
        corner = self._keys[slots] * self.size
        if self.representation == "centroid":
            return corner + self._sums[slots] / self._count[slots, None]
        n = self._raw_n[slots]
        rows = np.repeat(np.arange(len(slots)), n)
        cols = np.arange(len(rows)) - np.repeat(np.cumsum(n) - n, n)
        return corner[rows] + self._raw[slots[rows], cols]

    def voxels(self, keys: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Per-voxel state (copies), of the given (Q, 3) keys or of all voxels.

        keys (V, 3) int64; count (V,) int64; sums (V, 3) m, relative to each voxel's corner
        ``keys * voxel_size``; outer (V, 6) m^2 in ``OUTER_INDEX`` order; last_seen (V,) s;
        evidence (V,) int32.
        """
        s = self._slots(keys)
        return {
            "keys": self._keys[s].copy(),
            "count": self._count[s].copy(),
            "sums": self._sums[s].copy(),
            "outer": self._outer[s].copy(),
            "last_seen": self._last_seen[s].copy(),
            "evidence": self._evidence[s].copy(),
        }

    def forget(self, stamp: float, position: np.ndarray) -> np.ndarray:
        """Run the radius/age/cap pass now (no slack). Returns the removed (R, 3) keys."""
        return self._forget(float(stamp), np.asarray(position, dtype=np.float64))

    def stats(self) -> dict[str, int]:
        """Counters: voxels, capacity, scans, points_merged, points_invalid, dropped_radius,
        dropped_age, dropped_cap, cleared, forget_passes."""
        return {"voxels": len(self), "capacity": self._capacity, **self._stats}

    # ----------------------------------------------------------------- internals

    def _slots(self, keys: np.ndarray | None) -> np.ndarray:
        if keys is None:
            return np.flatnonzero(self._alive)
        k = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
        s = self._hash.find(pack_keys(k))
        return s[s >= 0]

    def _merge(self, pts: np.ndarray, stamp: float) -> np.ndarray:
        """Add the scan's voxel moments to the store; returns the (V,) slots hit."""
        if len(pts) == 0:
            return np.zeros(0, np.int64)
        grid = voxelize(pts, np.full(3, self.size))
        packed = pack_keys(grid.keys)
        slots = self._hash.find(packed)
        new = np.flatnonzero(slots < 0)
        if len(new):
            fresh = self._take(len(new))
            slots[new] = fresh
            self._hash.insert(packed[new], fresh)
            self._keys[fresh] = grid.keys[new]
            self._packed[fresh] = packed[new]
            self._alive[fresh] = True
            self._count[fresh] = 0
            self._sums[fresh] = 0.0
            self._outer[fresh] = 0.0
            self._evidence[fresh] = 0
            self._raw_n[fresh] = 0
            self._raw_head[fresh] = 0
        # The scan's voxels are distinct, so fancy-indexed += adds exactly once per slot.
        self._count[slots] += grid.counts
        self._sums[slots] += grid.sums
        self._outer[slots] += grid.outer
        self._last_seen[slots] = stamp
        self._last_scan[slots] = self._scans
        self._evidence[slots] = np.minimum(self._evidence[slots] + 1, self.max_evidence)
        if self.keep_points:
            self._keep_recent(grid, slots)
        return slots

    def _keep_recent(self, grid: VoxelGrid, slots: np.ndarray) -> None:
        """Ring buffer of the newest ``keep_points`` raw points per voxel (relative to corner).

        From each scan, up to ``keep_points`` of a voxel's points enter the ring, evenly spaced
        in input order (a lidar's input order runs along its rings, so they spread over the
        voxel rather than bunch at one end); they overwrite the oldest ones."""
        k = self.keep_points
        counts = grid.counts
        take = np.minimum(counts, k)
        voxel = np.repeat(np.arange(len(counts)), take)
        j = np.arange(len(voxel)) - np.repeat(np.cumsum(take) - take, take)
        # Evenly spaced picks among the voxel's points, not just its first ones.
        pick = grid.starts[voxel] + (j * counts[voxel]) // take[voxel]
        local = np.stack([grid.local[a][pick] for a in range(3)], axis=1)
        s = slots[voxel]
        col = (self._raw_head[s] + j) % k
        self._raw[s, col] = local.astype(np.float32)
        self._raw_head[slots] = (self._raw_head[slots] + take) % k
        self._raw_n[slots] = np.minimum(self._raw_n[slots] + take, k)

    def _clear(self, pts: np.ndarray, origin: np.ndarray) -> np.ndarray:
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
        if len(pts) > self.clear_rays:
            pts = pts[self._rng.choice(len(pts), self.clear_rays, replace=False)]
        d = pts - origin
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        ok = dist > 3 * size
        d, dist, pts = d[ok], dist[ok], pts[ok]
        u = d / dist[:, None]
        # Nothing is kept beyond the radius: marching further (a stray return kilometres away)
        # would only cost time.
        rng_ = np.minimum(dist, self.params.radius + 2 * size)
        # One sample per voxel length: a ray may skip a corner it clips, which only delays
        # clearing there; half steps would double the cost for little.
        step = size
        n = np.maximum(np.floor((rng_ - 2 * size) / step).astype(np.int64), 0)
        ray = np.repeat(np.arange(len(n)), n)
        t = (np.arange(len(ray)) - np.repeat(np.cumsum(n) - n, n) + 0.5) * step
        # Column by column and packed on the fly: no (S, 3) temporaries. Samples lie between
        # the origin and in-range hits, so they are in range too.
        packed = np.zeros(len(ray), np.int64)
        for a in range(3):  # three axes
            k = np.floor((origin[a] + u[ray, a] * t) / size).astype(np.int64) + _OFFS[a]
            packed |= k << _SHIFTS[a]
        # Consecutive samples of one ray often share a voxel: look each up once.
        first = np.ones(len(packed), bool)
        first[1:] = (packed[1:] != packed[:-1]) | (ray[1:] != ray[:-1])
        ray, packed = ray[first], packed[first]
        slot = self._hash.find(packed)
        met = slot >= 0
        ray, slot = ray[met], slot[met]
        met = self._last_scan[slot] != self._scans  # hit by this scan: seen, not seen through
        ray, slot = ray[met], slot[met]
        if len(slot) == 0:
            return np.zeros((0, 3), np.int64)

        uniq, inv = np.unique(slot, return_inverse=True)
        corner = self._keys[uniq] * size
        cnt = self._count[uniq].astype(np.float64)
        mean = self._sums[uniq] / cnt[:, None]
        cov = np.empty((len(uniq), 3, 3))
        for col, (a, b) in enumerate(OUTER_INDEX):  # six entries, not a loop over voxels
            v = self._outer[uniq, col] / cnt - mean[:, a] * mean[:, b]
            cov[:, a, b] = v
            cov[:, b, a] = v
        evals, normal = sym3_eigen(cov)
        # Planar needs spread in two directions: a lidar ring leaves a line of points in a
        # voxel, whose "normal" is any direction across the line.
        planar = (cnt >= 4) & (evals[:, 0] < 0.25 * evals[:, 1]) & (evals[:, 1] > (0.1 * size) ** 2)
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
