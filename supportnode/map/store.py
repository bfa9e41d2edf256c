"""Incremental voxel map: posed scans merged into per-voxel moments, aged, cropped, ray-cleared.

State lives in the map frame (z up, metres). Every occupied voxel (edge ``voxel_size``) keeps the
moments of the points merged into it relative to its own corner, as
:func:`supportnode.geometry.voxels.voxelize` computes them (up to the order of summation), so
merging scan after scan is exact (merging two scans equals voxelizing their union, to rounding)
and stays precise far from the origin.

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
from supportnode.geometry.transform import transform_points
from supportnode.kernels.places import kept_points
from supportnode.map.clearing import Clearing
from supportnode.map.forget import Forgetting
from supportnode.map.hash import KeyHash
from supportnode.map.keys import pack_keys
from supportnode.map.merge import Merging
from supportnode.params import MapParams

REPRESENTATIONS = ("stable", "recent", "centroid")


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


class VoxelMap(Merging, Clearing, Forgetting):
    """Incremental voxel map of posed scans (see the module docstring).

    params: ``MapParams`` (radius, max_age, max_voxels, voxel_size, clear_free_space).
    representation: points handed to detection by :meth:`points`:
        ``"stable"`` keeps the first ``keep_points`` raw points a voxel receives (float32
        relative to its corner, evenly spread over the scans' points in it) and renews them
        only when a scan shows that what the voxel holds has changed (see
        :meth:`_keep_first`; a voxel that rays see through loses evidence and goes instead):
        on a static scene the detection input, and so every cluster and id, stays the same
        from scan to scan, and changes only where the map changes;
        ``"recent"`` keeps the ``keep_points`` newest raw points of every voxel (a ring: every
        scan that hits a voxel replaces them, so clusters of partly seen objects flicker);
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
        representation: str = "stable",
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
        self.keep_points = int(keep_points) if representation != "centroid" else 0
        self.max_evidence = int(max_evidence)
        self.clear_rays = int(clear_rays)
        self.size = float(self.params.voxel_size)
        self.clear_tolerance = self.size if clear_tolerance is None else float(clear_tolerance)
        self.crop_slack = 0.05 * self.params.radius if crop_slack is None else float(crop_slack)
        self.age_slack = 0.1 * self.params.max_age if age_slack is None else float(age_slack)
        self._rng = np.random.default_rng(seed)
        self._pending = None
        self._buffers: dict[str, np.ndarray] = {}  # per-scan scratch, see _buffer
        self._hash = KeyHash()
        self._alloc_store(1 << 12)
        self._free = np.arange(self._capacity - 1, -1, -1, dtype=np.int64)  # stack, pop at end
        self._nfree = self._capacity
        self._scans = 0
        # Bumped whenever what points() returns may have changed: equal versions of one map,
        # equal points (the node then reuses its detection).
        self.version = 0
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
                "renewed",
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
        # Sums and outer products side by side: a scan merges them with one gather and one
        # scatter of (V, 9) rows instead of two of each.
        self._moments = np.zeros((capacity, 9))
        self._sums = self._moments[:, :3]
        self._outer = self._moments[:, 3:]
        self._last_seen = np.zeros(capacity)
        self._last_scan = np.full(capacity, -1, np.int64)
        self._evidence = np.zeros(capacity, np.int32)
        k = max(self.keep_points, 1)
        self._raw = np.zeros((capacity, k, 3), np.float32)
        # The kept points in the map frame (corner + raw, float64), written with _raw: points()
        # is then one gather of rows, not a gather, a repeat of the corners and an add.
        self._pts = np.zeros((capacity, k, 3))
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
                "_moments",
                "_last_seen",
                "_last_scan",
                "_evidence",
                "_raw",
                "_pts",
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
        keys = self._keys[slots]  # a fancy-indexed gather: already a copy
        self.version += int(len(slots) > 0)
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

    def integrate(
        self,
        points: np.ndarray,
        pose: np.ndarray,
        stamp: float,
        *,
        in_map_frame: bool = False,
    ) -> Touched:
        """Merge one scan and clear along its rays: :meth:`merge` then :meth:`settle`.

        points: (N, 3) float, metres, in the sensor frame (or already in the map frame with
            ``in_map_frame=True``). Non-finite points (a driver's misses) are skipped.
        pose: (4, 4) sensor-to-map transform; its translation is the ray origin for clearing
            and the centre of the radius crop.
        stamp: seconds, non-decreasing across calls (ages are measured from the newest stamp).
        Returns the voxels hit and removed, and the scan's bounding box (:class:`Touched`).
        """
        slots, keys, lo, hi = self._merge_scan(points, pose, stamp, in_map_frame)
        removed = self.settle()
        # The scan's keys are those of its slots: no gather from the store unless clearing
        # or forgetting removed some of them.
        alive = self._alive[slots]
        if not alive.all():
            keys = keys[alive]
        return Touched(keys, removed, lo, hi)

    def merge(
        self,
        points: np.ndarray,
        pose: np.ndarray,
        stamp: float,
        *,
        in_map_frame: bool = False,
    ) -> Touched:
        """:meth:`integrate`'s first half: the scan's voxels merged (its points, pose and stamp
        as there); its free-space clearing and the forgetting pass wait for :meth:`settle`
        (``removed`` is empty). The node takes its detection's points between the two: the
        clearing then stays off the detection's path. A merge settles a scan left unsettled
        first (its removed keys then go unreported)."""
        _, keys, lo, hi = self._merge_scan(points, pose, stamp, in_map_frame)
        return Touched(keys, np.zeros((0, 3), np.int64), lo, hi)

    def settle(self) -> np.ndarray:
        """:meth:`integrate`'s second half for the last merged scan: free-space clearing along
        its rays, then the radius, age and cap pass when due; returns the removed (R, 3)
        int64 keys (none when no scan waits)."""
        pending, self._pending = self._pending, None
        if pending is None:
            return np.zeros((0, 3), np.int64)
        cols, origin, stamp = pending
        removed = []
        if self.params.clear_free_space and len(cols[0]):
            removed.append(self._clear(cols, origin))
        removed.append(self._maybe_forget(stamp, origin))
        return np.concatenate(removed)

    def points(self, keys: np.ndarray | None = None) -> np.ndarray:
        """Representative points for detection: (P, 3) float64, map frame, metres.

        keys: (Q, 3) int64 voxels to take them from (e.g. ``Touched.keys``; absent ones are
        skipped), None for the whole map. "stable" and "recent": up to ``keep_points`` raw
        points per voxel; "centroid": one point per voxel.
        """
        if keys is None and self.representation != "centroid":
            # Every slot at once, in slot order: a dead slot keeps no points (_remove empties
            # it), so one comparison over the store replaces finding the live slots.
            return kept_points(self._pts, self._raw_n)
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
        not over the map's points; without a rotation (or the identity), a pass of integer
        comparisons on the key columns (a map of 400k voxels: a few ms)."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        live = len(self)
        if rotation is None or np.array_equal(rotation, np.eye(3)):
            # Voxel kx holds x in [kx * size, (kx + 1) * size): it may meet [lo, hi] only if
            # floor(lo / size) <= kx <= floor(hi / size); one more on each side against
            # round-off (a superset is enough).
            klo = np.floor(lo / self.size).astype(np.int64) - 1
            khi = np.floor(hi / self.size).astype(np.int64) + 1
            sel = self._alive.copy()
            for a in range(2):  # x and y columns, compared in place: no (V, 3) temporaries
                col = self._keys[:, a]
                sel &= col >= klo[a]
                sel &= col <= khi[a]
            slots = np.flatnonzero(sel)
        else:
            alive = np.flatnonzero(self._alive)
            centre = transform_points((self._keys[alive] + 0.5) * self.size, rotation)
            pad = self.size * np.sqrt(3.0) / 2.0  # a point lies within this of its centre
            sel = np.ones(len(alive), bool)
            for a in range(2):  # x and y
                sel &= centre[:, a] >= lo[a] - pad
                sel &= centre[:, a] <= hi[a] + pad
            slots = alive[sel]
        if len(slots) >= max_share * live:
            return None
        return self._points_of(slots)

    def _points_of(self, slots: np.ndarray) -> np.ndarray:
        if self.representation == "centroid":
            corner = self._keys[slots] * self.size
            return corner + self._sums[slots] / self._count[slots, None]
        k = self._raw.shape[1]
        # Rings fill from slot 0, so the kept points of a voxel are its first n columns: one
        # mask over (V, k) gives their rows in order, and one gather of those rows the points
        # (a boolean mask over (V, k, 3) costs 2-3x).
        have = np.arange(k) < self._raw_n[slots][:, None]
        rows = (slots[:, None] * k + np.arange(k))[have]
        return np.take(self._pts.reshape(-1, 3), rows, axis=0)

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
        """Run the radius/age/cap pass now (no slack); returns the removed (R, 3) keys."""
        return self._forget(float(stamp), np.asarray(position, dtype=np.float64))

    def stats(self) -> dict[str, int]:
        """Counters: voxels, capacity, scans, points_merged, points_invalid, dropped_radius,
        dropped_age, dropped_cap, cleared, renewed (voxels whose kept points a scan replaced),
        forget_passes."""
        return {"voxels": len(self), "capacity": self._capacity, **self._stats}

    # ----------------------------------------------------------------- internals

    def _slots(self, keys: np.ndarray | None) -> np.ndarray:
        if keys is None:
            return np.flatnonzero(self._alive)
        k = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
        s = self._hash.find(pack_keys(k))
        return s[s >= 0]
