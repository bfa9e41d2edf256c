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
from itertools import pairwise
from typing import NamedTuple

import numpy as np

from supportnode.errors import InputError
from supportnode.geometry.linalg import sym3_eigen_entries
from supportnode.geometry.transform import transform_points
from supportnode.geometry.voxels import OUTER_INDEX, argsort_keys, voxelize
from supportnode.params import MapParams

# Keys are packed into one non-negative int64: 22 bits for x and y, 19 for z, each around an
# offset of half its range: |x|, |y| < 2^21 voxels (+-105 km at 5 cm), |z| < 2^18 (+-13 km).
_BITS_XY, _BITS_Z = 22, 19
_OFFS = np.array([1 << (_BITS_XY - 1), 1 << (_BITS_XY - 1), 1 << (_BITS_Z - 1)], np.int64)
_SHIFTS = (_BITS_XY + _BITS_Z, _BITS_Z, 0)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: scatters spatially close keys
_EMPTY, _TOMB = -1, -2
_MAGIC = float(1 << 52)  # x + 2^52 holds an integer 0 <= x < 2^52 as its mantissa bits
_FILTER_BITS = 3  # KeyHash.filter has 2^3 cells per table position
REPRESENTATIONS = ("stable", "recent", "centroid")
_CHUNK = 1 << 15  # ray samples per chunk in VoxelMap._clear (~256 KB per temporary)
# Renewal of a voxel's kept points: a ray through them is one passing within this many voxel
# edges of one (lidar returns are centimetres apart at a few metres), tested on up to
# _SEE_RAYS of the scan's points in the voxel and in each neighbour.
_SEE_RADIUS = 0.3
_SEE_RAYS = 32
# ... and that lies before the scan's point by at least this many voxel edges: a ray to a
# wall's foot passes close over the floor points just in front of it.
_SEE_BEFORE = 0.5
# ... and within this share of the kept point's distance off the scan's plane.
_SEE_OFF = 1.0
# The noise floor of a scan: this percentile of its dense voxels' own estimates (see
# _plane_noise).
_NOISE_PERCENTILE = 90.0
# The 27 steps from a voxel to itself and its neighbours, x slowest.
_STEPS = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)


def pack_keys(keys: np.ndarray) -> np.ndarray:
    """(N, 3) int64 voxel keys -> (N,) non-negative int64; raises InputError out of range."""
    k = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    # Column by column, shifted in place: numpy reduces and combines the short axis of an
    # (N, 3) array several times slower, and (N, 3) temporaries cost their pages.
    out = np.zeros(len(k), np.int64)
    for a in range(3):  # three axes
        col = k[:, a] + _OFFS[a]
        if len(col) and (col.min() < 0 or col.max() >= 2 * _OFFS[a]):
            raise InputError(
                "points too far from the map origin for this voxel size "
                f"(|key| must stay below 2^{_BITS_XY - 1} in x, y and 2^{_BITS_Z - 1} in z)"
            )
        col <<= _SHIFTS[a]
        out |= col
    return out


def coordinate_range(voxel_size: float) -> np.ndarray:
    """(3,) metres: the largest |x|, |y|, |z| a map point may have at this voxel size (what
    :func:`pack_keys` can hold, a voxel short of it)."""
    return (_OFFS - 1).astype(np.float64) * float(voxel_size)


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

    Alongside, ``filter`` counts the live keys per cell of a finer hash (2^_FILTER_BITS cells
    per table position, uint8, saturating at 255: a saturated cell stays "maybe" until the next
    rebuild). A zero cell proves a key absent: at 1/16 or less of the cells occupied it drops
    most absent queries with one lookup, where the table itself leaves up to half of them to
    probe on (:meth:`maybe_present`).
    """

    def __init__(self, capacity: int = 1 << 12) -> None:
        self._alloc(max(1 << 4, 1 << int(np.ceil(np.log2(capacity)))))
        self.size = 0

    def _alloc(self, capacity: int) -> None:
        self.keys = np.full(capacity, _EMPTY, dtype=np.int64)
        self.vals = np.zeros(capacity, dtype=np.int64)
        self.tombs = 0
        self._shift = np.uint64(64 - int(np.log2(capacity)))
        self.filter = np.zeros(capacity << _FILTER_BITS, dtype=np.uint8)
        self._fshift = np.uint64(64 - int(np.log2(capacity)) - _FILTER_BITS)

    @property
    def capacity(self) -> int:
        return len(self.keys)

    def _home(self, q: np.ndarray, shift: np.uint64 | None = None) -> np.ndarray:
        # Views, not copies: packed keys are non-negative and the shifted hash fits in int64.
        h = np.ascontiguousarray(q, dtype=np.int64).view(np.uint64) * _GOLDEN
        h >>= self._shift if shift is None else shift
        return h.view(np.int64)

    def _count(self, q: np.ndarray, sign: int) -> None:
        """Add ``sign`` (+-1) to the filter cells of (Q,) distinct packed keys."""
        cells, n = np.unique(self._home(q, self._fshift), return_counts=True)
        c = self.filter[cells].astype(np.int64)
        self.filter[cells] = np.where(c == 255, 255, np.clip(c + sign * n, 0, 255))

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

    def maybe_present(self, q: np.ndarray) -> np.ndarray:
        """Indices into (Q,) packed keys of those that may be present (the others are not):
        one lookup in ``filter`` per query, for many queries of which few are present (ray
        samples in free space); :meth:`find_present` settles the rest."""
        # Compared to zero first: numpy finds the nonzero entries of bool 5x faster than uint8.
        return np.flatnonzero(np.take(self.filter, self._home(q, self._fshift)) != 0)

    def find_present(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Indices into (Q,) packed keys of those present, ascending, and their slots.

        Unlike :meth:`find`, no (Q,) result: suits queries of which few are present."""
        idx = np.arange(len(q))
        pos = self._home(q)
        mask = self.capacity - 1
        hits, hit_pos = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        while idx.size:
            k = np.take(self.keys, pos)
            hit = k == q[idx]
            hits.append(idx[hit])
            hit_pos.append(pos[hit])
            go_on = ~hit & (k != _EMPTY)  # tombstones do not end a probe chain
            idx, pos = idx[go_on], (pos[go_on] + 1) & mask
        found, at = np.concatenate(hits), np.concatenate(hit_pos)
        order = np.argsort(found, kind="stable")
        return found[order], self.vals[at[order]]

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
        self._count(q, 1)

    def delete(self, q: np.ndarray) -> None:
        """Remove (Q,) distinct packed keys that are in the table."""
        pos = self._locate(q)
        self._count(q[pos >= 0], -1)
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


def _plane_fits(
    count: np.ndarray, sums: np.ndarray, outer: np.ndarray, size: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Plane fits of voxel moments: count (V,), sums (V, 3) and outer (V, 6) relative to each
    voxel's corner (``OUTER_INDEX`` order), voxel edge ``size`` m. Returns the mean (V, 3)
    relative to the corner, eigenvalues (V, 3) ascending (m^2), the normal (V, 3) and
    ``planar`` (V,): at least four points spread in two directions (a lidar ring leaves a line
    of points in a voxel, whose "normal" is any direction across the line)."""
    cnt = count.astype(np.float64)
    mean = np.empty((len(cnt), 3))
    for a in range(3):  # three axes: a (V, 1) broadcast costs 3x
        np.divide(sums[:, a], cnt, out=mean[:, a])
    # The covariance's six entries as (V,) columns: what sym3_eigen would take out of an
    # (V, 3, 3) stack, without building it.
    evals, normal = sym3_eigen_entries(
        *(outer[:, col] / cnt - mean[:, a] * mean[:, b] for col, (a, b) in enumerate(OUTER_INDEX))
    )
    planar = (cnt >= 4) & (evals[:, 0] < 0.25 * evals[:, 1]) & (evals[:, 1] > (0.1 * size) ** 2)
    return mean, evals, normal, planar


def _plane_noise(smallest: np.ndarray, count: np.ndarray, among: np.ndarray) -> np.ndarray:
    """(V,) metres: the noise of a scan's points about the planes fitted in its voxels, from
    the smallest covariance eigenvalue (V,) m^2 of each voxel's count (V,) points. Each voxel's
    own estimate, unbiased (three of its degrees of freedom went into the fit), but never
    below the ``_NOISE_PERCENTILE`` percentile over the voxels with eight points or more: a
    plane through four or five points says little about the noise, and a sensor's noise is
    much the same from one voxel to the next. Not the median: a surface near a voxel's face
    is cut in two by it, and each half spreads less than the noise (a half-normal: 0.6 of it),
    so the median of a noisy scan's voxels says about half its noise. among: (V,) bool, the
    voxels that make the percentile (the planes; the others' estimates are still returned)."""
    n = count.astype(np.float64)
    var = np.maximum(smallest, 0.0) * n / np.maximum(n - 3.0, 1.0)
    dense = var[(n >= 8) & among]
    floor = float(np.percentile(dense, _NOISE_PERCENTILE)) if len(dense) else 0.0
    return np.sqrt(np.maximum(var, floor))


class _ScanGrid(NamedTuple):
    """One scan's voxels: keys (V, 3) int64 ascending, counts (V,), moments (V, 9): sums
    (V, 3) then outer (V, 6) relative to each voxel's corner, and the points' offsets from
    their voxel's corner, local (three (N,) columns), in one of two layouts:

    - by voxel, as :class:`~supportnode.geometry.voxels.VoxelGrid` has them: ``voxel`` None,
      voxel v's points are ``local[a][starts[v] : starts[v] + counts[v]]`` in input order;
    - in input order, as merging leaves them: ``voxel`` (N,) intp is each point's voxel and
      ``starts`` None; :meth:`VoxelMap._by_voxel` sorts the points of the voxels asked for.
    """

    keys: np.ndarray
    counts: np.ndarray
    starts: np.ndarray | None
    moments: np.ndarray
    local: list[np.ndarray]
    voxel: np.ndarray | None = None

    @property
    def sums(self) -> np.ndarray:
        return self.moments[:, :3]

    @property
    def outer(self) -> np.ndarray:
        return self.moments[:, 3:]


@dataclass
class Touched:
    """What one :meth:`VoxelMap.integrate` (or :meth:`VoxelMap.finish`) changed.

    keys: (T, 3) int64 voxels hit by the scan (all still in the map when returned, unless
        its clearing and forgetting were deferred: :meth:`VoxelMap.finish` may remove some).
    removed: (R, 3) int64 voxels removed by this call (free-space clearing and forgetting,
        including a previous scan's deferred ones that this call ran first: a voxel removed
        then and hit again by this scan is in both).
    lo, hi: (3,) float64 bounding box of the scan's points in the map frame, metres
        (lo > hi componentwise for an empty scan, and for :meth:`VoxelMap.finish`).
    """

    keys: np.ndarray
    removed: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


class VoxelMap:
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
        # The clearing and forgetting that integrate(defer_clear=True) left for finish():
        # the scan's map frame columns, its ray origin and its stamp.
        self._deferred: tuple[list[np.ndarray], np.ndarray, float] | None = None
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

    def __len__(self) -> int:
        return self._hash.size

    def integrate(
        self,
        points: np.ndarray,
        pose: np.ndarray,
        stamp: float,
        *,
        in_map_frame: bool = False,
        defer_clear: bool = False,
    ) -> Touched:
        """Merge one scan.

        points: (N, 3) float, metres, in the sensor frame (or already in the map frame with
            ``in_map_frame=True``). Non-finite points (a driver's misses) are skipped.
        pose: (4, 4) sensor-to-map transform; its translation is the ray origin for clearing
            and the centre of the radius crop.
        stamp: seconds, non-decreasing across calls (ages are measured from the newest stamp).
        defer_clear: only merge; the scan's free-space clearing and forgetting wait for
            :meth:`finish` (a node runs them while its detection works on the merged map's
            points). A clearing still pending from the previous scan runs first, here, so the
            map goes through the same states either way: scan k's clearing always comes
            before scan k + 1's merge.
        Returns the voxels hit and removed, and the scan's bounding box (:class:`Touched`).
        """
        pts = np.asarray(points, dtype=np.float64)
        pose = np.asarray(pose, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(f"points must be an (N, 3) array, got shape {pts.shape}")
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise InputError("pose must be a finite (4, 4) sensor-to-map transform")
        before = self.finish().removed
        # Column by column: numpy reduces the short axis of an (N, 3) array 5-20x slower.
        finite = np.isfinite(pts[:, 0] + pts[:, 1] + pts[:, 2])
        if not finite.all():
            self._stats["points_invalid"] += int((~finite).sum())
            pts = pts[finite]
        # The map frame points as three contiguous columns, what voxelizing works on: the
        # same operations as transform_points, written straight into columns.
        if in_map_frame:
            cols = [np.ascontiguousarray(pts[:, a]) for a in range(3)]
        else:
            rot, shift = pose[:3, :3], pose[:3, 3]
            cols = []
            for i in range(3):  # three output columns
                col = np.multiply(pts[:, 0], rot[i, 0])
                col += pts[:, 1] * rot[i, 1]
                col += pts[:, 2] * rot[i, 2]
                col += float(shift[i])
                cols.append(col)
        origin = pose[:3, 3].copy()
        npts = len(cols[0])
        self._scans += 1
        self._stats["scans"] += 1
        self._stats["points_merged"] += npts

        slots, keys = self._merge(cols, float(stamp), origin)
        lo = np.array([c.min() for c in cols]) if npts else np.full(3, np.inf)
        hi = np.array([c.max() for c in cols]) if npts else np.full(3, -np.inf)
        if defer_clear:
            if in_map_frame:  # columns that may share memory with the caller's points
                cols = [c if c.base is None else c.copy() for c in cols]
            self._deferred = (cols, origin, float(stamp))
            return Touched(keys, before, lo, hi)
        removed = [before, self._clear_and_forget(cols, origin, float(stamp))]
        # The scan's keys are those of its slots: no gather from the store unless clearing
        # or forgetting removed some of them.
        alive = self._alive[slots]
        if not alive.all():
            keys = keys[alive]
        return Touched(keys, np.concatenate(removed), lo, hi)

    @property
    def clear_pending(self) -> bool:
        """True while the last scan's clearing and forgetting wait for :meth:`finish`."""
        return self._deferred is not None

    def finish(self) -> Touched:
        """Run the clearing and forgetting that ``integrate(..., defer_clear=True)`` left
        pending (none: nothing happens). Returns what they removed, as a :class:`Touched`
        with no keys and an empty box (``removed`` (R, 3) int64)."""
        pending, self._deferred = self._deferred, None
        removed = (
            np.zeros((0, 3), np.int64) if pending is None else self._clear_and_forget(*pending)
        )
        return Touched(np.zeros((0, 3), np.int64), removed, np.full(3, np.inf), np.full(3, -np.inf))

    def _clear_and_forget(self, cols: list[np.ndarray], origin: np.ndarray, stamp: float):
        """The end of a scan's integration: free-space clearing along its rays, then the
        radius, age and cap pass when due; returns the removed (R, 3) keys."""
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
            have = np.arange(self._raw.shape[1]) < self._raw_n[:, None]
            return np.take(self._pts.reshape(-1, 3), np.flatnonzero(have), axis=0)
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
        """Run the radius/age/cap pass now (no slack), after any clearing still pending (its
        removed keys are not returned: call :meth:`finish` first for those). Returns the
        removed (R, 3) keys."""
        self.finish()
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

    def _buffer(self, name: str, n: int, dtype: type) -> np.ndarray:
        """(n,) scratch array kept across scans: contents undefined, except that a new one
        is zeroed (``_voxelize`` keeps its "mark" table all False between calls).

        Per-point temporaries of a scan are megabytes; fresh ones cost a page fault per 4 KB
        on every scan (about as much as the arithmetic on them), reused ones do not."""
        buf = self._buffers.get(name)
        if buf is None or len(buf) < n or buf.dtype != dtype:
            buf = np.zeros(max(n, 2 * len(buf) if buf is not None else 0), dtype)
            self._buffers[name] = buf
        return buf[:n]

    def _voxelize(self, cols: list[np.ndarray]) -> _ScanGrid:
        """:func:`~supportnode.geometry.voxels.voxelize` of the scan's (N,) x, y, z columns,
        map frame: the same voxels, counts and offsets, moments equal up to rounding, the
        points left in input order (see :class:`_ScanGrid`). Scans whose bounding box holds
        2^53 voxels or more (linear keys beyond float64's integers) go to ``voxelize``
        itself."""
        size = self.size
        n = len(cols[0])
        # Float keys, then offsets from the corner (below), in buffers kept across scans.
        kcols = []
        for a, c in enumerate(cols):  # three axes
            kc = np.divide(c, size, out=self._buffer(f"key{a}", n, np.float64))
            kcols.append(np.floor(kc, out=kc))
        lo = np.array([c.min() for c in kcols])
        hi = np.array([c.max() for c in kcols])
        far = max(np.abs(lo).max(), np.abs(hi).max()) >= 2**40
        dims = (hi - lo + 1.0) if not far else np.full(3, np.inf)
        if float(np.prod(dims)) >= 2.0**53:  # linear keys not exact in float64
            grid = voxelize(np.stack(cols, axis=1), np.full(3, size))  # raises when too far
            moments = np.concatenate([grid.sums, grid.outer], axis=1)
            return _ScanGrid(grid.keys, grid.counts, grid.starts, moments, grid.local)
        # Linear key of each point's voxel in the scan's box, in float64 (exact: integers
        # below 2^53) and in place, converted once.
        lin_f = self._buffer("lin_f", n, np.float64)
        np.subtract(kcols[0], lo[0], out=lin_f)
        lin_f *= float(dims[1])
        lin_f += kcols[1]
        lin_f -= lo[1]
        lin_f *= float(dims[2])
        lin_f += kcols[2]
        lin_f -= lo[2]
        lin = self._buffer("lin", n, np.int64)
        lin[...] = lin_f
        dims = dims.astype(np.int64)
        top = int(np.prod(dims)) - 1
        # Each point's voxel as its rank among the occupied keys, ascending (intp: what
        # bincount takes; other index types it converts on every call).
        point_voxel = self._buffer("point_voxel", n, np.intp)
        if top < max(8 * n, 1 << 20):
            # Few keys in the box (the usual case): the occupied ones from a mark table
            # (reset after use, so it stays all False), the ranks by a table lookup.
            mark = self._buffer("mark", top + 1, np.bool_)
            mark[lin] = True
            lin_of_voxel = np.flatnonzero(mark)
            mark[lin_of_voxel] = False
            rank = self._buffer("rank", top + 1, np.intp)
            rank[lin_of_voxel] = np.arange(len(lin_of_voxel))
            np.take(rank, lin, out=point_voxel)
        else:
            # A box too large for a table (a large room, a far return): the occupied keys by
            # sorting the points' keys (any order among equal keys would do; radix is the
            # fastest), each point's rank from its place in that order. These scans went to
            # voxelize, whose gathers and 9 reduceat over ~1e5 voxels cost 3x the sort.
            order = argsort_keys(lin, top=top)
            lin_sorted = np.take(lin, order)
            new = np.empty(n, bool)
            new[0] = True
            np.not_equal(lin_sorted[1:], lin_sorted[:-1], out=new[1:])
            lin_of_voxel = lin_sorted[new]
            point_voxel[order] = np.cumsum(new) - 1
        nvox = len(lin_of_voxel)
        counts = np.bincount(point_voxel, minlength=nvox)
        rem, kz = np.divmod(lin_of_voxel, dims[2])
        kx, ky = np.divmod(rem, dims[1])
        keys = np.stack([kx, ky, kz], axis=1) + lo.astype(np.int64)
        # Offsets from the voxel corner, as voxelize computes them, left in input order, and
        # the moments summed by bincount in input order: no sort of the scan's points and no
        # gather of them (a stable sort, three gathers and nine reduceat cost 2-3x the nine
        # bincounts). The sums are those of voxelize up to rounding (each voxel's points are
        # added one after the other, starting from zero, where reduceat adds the first to a
        # pairwise sum of the others): deterministic, as exact as before, not the same bits.
        # Only the kept points need points by voxel, and only of a few voxels (_by_voxel).
        local = []
        moments = np.empty((nvox, 9))
        for a in range(3):  # three axes
            off = np.multiply(kcols[a], size, out=kcols[a])
            np.subtract(cols[a], off, out=off)
            local.append(off)
            moments[:, a] = np.bincount(point_voxel, weights=off, minlength=nvox)
        prod = self._buffer("prod", n, np.float64)
        for col, (a, b) in enumerate(OUTER_INDEX):  # six entries
            np.multiply(local[a], local[b], out=prod)
            moments[:, 3 + col] = np.bincount(point_voxel, weights=prod, minlength=nvox)
        return _ScanGrid(keys, counts, None, moments, local, point_voxel)

    def _by_voxel(self, grid: _ScanGrid, need: np.ndarray | None = None) -> _ScanGrid:
        """``grid`` with the points of the voxels ``need`` (V,) bool (None: all) by voxel, in
        input order within each (see :class:`_ScanGrid`); the other voxels' ``starts`` are
        meaningless and their points absent. A stable sort of the points asked for puts each
        voxel's points in the order a stable sort of all of them would: the same evenly spaced
        picks. In steady state few voxels take points or are tested for renewal (new voxels,
        ones not yet full, and the neighbourhoods of renewal candidates: of an os128 scan's
        131k points in a room, some thousands, ~30k with 1 cm of noise), so this sorts and
        gathers only those."""
        if grid.voxel is None:  # sorted already (voxelize's grid)
            return grid
        nvox = len(grid.counts)
        if need is None:
            idx, voxel, counts = None, grid.voxel, grid.counts
        else:
            idx = np.flatnonzero(np.take(need, grid.voxel))
            voxel, counts = np.take(grid.voxel, idx), np.where(need, grid.counts, 0)
        if nvox <= 1 << 16:
            # 16-bit ranks: numpy's stable sort of uint16 is one radix pass.
            order = np.argsort(voxel.astype(np.uint16), kind="stable")
        else:
            order = argsort_keys(voxel, top=nvox - 1)
        if idx is not None:
            order = np.take(idx, order)
        starts = np.cumsum(counts) - counts
        local = [np.take(c, order) for c in grid.local]
        return grid._replace(starts=starts, local=local, voxel=None)

    def _merge(
        self, cols: list[np.ndarray], stamp: float, origin: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Add the scan's voxel moments to the store; returns the (V,) slots hit and their
        (V, 3) keys (a new array, not a view of the store)."""
        if len(cols[0]) == 0:
            return np.zeros(0, np.int64), np.zeros((0, 3), np.int64)
        grid = self._voxelize(cols)
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
            self._moments[fresh] = 0.0
            self._evidence[fresh] = 0
            self._raw_n[fresh] = 0
            self._raw_head[fresh] = 0
        # The scan's voxels are distinct, so fancy-indexed += adds exactly once per slot.
        self._count[slots] += grid.counts
        # Gather, add, scatter: the same sums as fancy-indexed +=, at half its cost on rows.
        moments = np.take(self._moments, slots, axis=0)
        moments += grid.moments
        self._moments[slots] = moments
        self._last_seen[slots] = stamp
        self._last_scan[slots] = self._scans
        self._evidence[slots] = np.minimum(self._evidence[slots] + 1, self.max_evidence)
        if self.representation == "stable":
            self._keep_first(grid, packed, slots, origin)
        else:  # "recent" takes new points, "centroid" new sums, on every scan
            self.version += 1
            if self.keep_points:
                self._keep_recent(self._by_voxel(grid), slots)
        return slots, grid.keys

    def _keep_first(
        self, grid: _ScanGrid, packed: np.ndarray, slots: np.ndarray, origin: np.ndarray
    ) -> None:
        """Fill the free places of each voxel's ``keep_points`` kept points, in order, with
        evenly spaced picks (input order: along a lidar's rings) from this scan's points in
        it; voxels already full keep theirs unless this scan shows that what they hold has
        changed, and then its points replace them. Rays passing through remove what left
        (see :meth:`_clear`), but not from a voxel that still holds something: an object
        lifted off a board leaves the board's points in the voxels it stood in. (Emptying the
        points of a voxel as soon as one ray sees through it made clusters at the edges of
        objects flicker with the viewpoint: evidence decides, as for "recent".) Changed: this
        scan's points in the voxel make a plane (at least four, spread in two directions), a
        kept point lies off it by more than a fifth of a voxel and 3.5 times their noise (see
        _plane_noise), and a ray of this scan passed through that kept point (see
        _seen_through: a voxel holding two faces shows either from its own side). Fewer
        points, or a line of them (one lidar ring), say nothing."""
        k = self.keep_points
        n = self._raw_n[slots]
        cnt = grid.counts
        # The voxels whose points are needed by voxel (_by_voxel): those with free places
        # (renewed ones are among the candidates, added below).
        need = n < k
        had = np.flatnonzero((n > 0) & (cnt >= 4))
        if len(had):
            moments = np.take(grid.moments, had, axis=0)
            count = cnt[had]
            seen, evals, normal, planar = _plane_fits(
                count, moments[:, :3], moments[:, 3:], self.size
            )
            # Only a plane says where the kept points should lie (not a line: one lidar ring).
            # Most voxels are planes: the tests below run on all (each voxel's result is its
            # own), and only the end keeps the planes, rather than gathering them first.
            s = slots[had]
            raw = self._raw[s]  # (V, k, 3) float32, relative to the corner like seen
            # In float64 from the start (what mixing float32 into float64 products does anyway,
            # once rather than per product), in place.
            wide = raw.astype(np.float64)
            dist = wide[:, :, 0] * normal[:, 0, None]
            dist += wide[:, :, 1] * normal[:, 1, None]
            dist += wide[:, :, 2] * normal[:, 2, None]
            dist -= np.einsum("ij,ij->i", seen, normal)[:, None]
            np.abs(dist, out=dist)
            dist[np.arange(k)[None, :] >= n[had, None]] = 0.0  # places not filled yet
            noise = _plane_noise(evals[:, 0], count, planar)
            tol = np.maximum(0.2 * self.size, 3.5 * noise)
            # Column by column: numpy reduces the short axis of a (V, k) array several times
            # slower.
            most = dist[:, 0].copy()
            for j in range(1, k):  # keep_points columns
                np.maximum(most, dist[:, j], out=most)
            off = np.flatnonzero(planar & (most > tol))
            # The candidates' rays come from the scan's points in them and their neighbours.
            pairs = self._neighbour_pairs(grid, packed, had[off])
            need[pairs[1]] = True
            grid = self._by_voxel(grid, need)
            seen_through = self._seen_through(
                grid, had[off], pairs, raw[off], dist[off], origin, 3.0 * noise[off]
            )
            renew = s[off[seen_through]]
            self._raw_n[renew] = 0
            self._stats["renewed"] += len(renew)
        else:
            grid = self._by_voxel(grid, need)
        room = k - self._raw_n[slots]
        sel = np.flatnonzero(room > 0)
        if len(sel) == 0:
            return
        self.version += 1  # new voxels, renewed ones, or ones not yet full take points
        counts = grid.counts[sel]
        take = np.minimum(counts, room[sel])
        rep = np.repeat(np.arange(len(sel)), take)
        j = np.arange(len(rep)) - np.repeat(np.cumsum(take) - take, take)
        pick = grid.starts[sel][rep] + (j * counts[rep]) // take[rep]
        s = slots[sel]
        dest = s[rep] * k + self._raw_n[s][rep] + j
        vals = np.empty((len(pick), 3), np.float32)
        for a in range(3):  # three axes
            vals[:, a] = grid.local[a][pick]
        self._raw.reshape(-1, 3)[dest] = vals
        self._pts.reshape(-1, 3)[dest] = (self._keys[s] * self.size)[rep] + vals
        self._raw_n[s] += take.astype(np.int32)

    @staticmethod
    def _neighbour_pairs(
        grid: _ScanGrid, packed: np.ndarray, vox: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The pairs of a candidate, one of the scan's voxels ``vox`` (C,), and one of the
        scan's voxels among its 27 neighbours (itself included), as two (P,) arrays: candidate
        * 27 + step (into ``_STEPS``), ascending, and the neighbour's index into the scan's
        voxels. packed: (V,) ascending packed keys of the scan's voxels."""
        if len(vox) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        nb_keys = grid.keys[vox][:, None, :] + _STEPS[None, :, :]  # (C, 27, 3)
        nb_packed = pack_keys(nb_keys.reshape(-1, 3))
        at = np.minimum(np.searchsorted(packed, nb_packed), len(packed) - 1)
        pair = np.flatnonzero(packed[at] == nb_packed)  # (candidate, neighbour) pairs found
        return pair, at[pair]

    def _seen_through(
        self,
        grid: _ScanGrid,
        vox: np.ndarray,
        pairs: tuple[np.ndarray, np.ndarray],
        raw: np.ndarray,
        off: np.ndarray,
        origin: np.ndarray,
        margin: np.ndarray,
    ) -> np.ndarray:
        """(C,) bool: did a ray of this scan pass through one of the kept points raw (C, k, 3)
        (relative to the corner) of the scan's voxels ``vox`` (C,), which lie off the plane of
        the scan's points in the voxel by off (C, k) metres (0: a place not filled)?
        pairs: :meth:`_neighbour_pairs` of vox (grid must have their neighbours' points by
        voxel). margin: (C,) metres, at least this much before (the noise of the scan's points
        along the ray).

        A ray to one of the scan's points p in the voxel or its 26 neighbours passes within
        ``_SEE_RADIUS`` voxels of a kept point q, and no further than q lies off the plane (a
        ray grazing a floor passes close to the floor's own points in front of p, and noise
        lifts some of them), and q lies before p by at least ``_SEE_BEFORE`` voxels or the
        margin. A voxel holding two faces (a floor meeting a wall, a table's edge) shows one
        of them from one side and the other from the other, but no ray passes through the face
        it does not show: only what left (a box lifted off a board, whose board is now seen
        where the box's foot stood) is renewed. Up to ``_SEE_RAYS`` evenly spaced scan points
        per voxel."""
        if len(vox) == 0:
            return np.zeros(0, bool)
        size = self.size
        pair, pv = pairs
        pc = pair // len(_STEPS)
        counts = grid.counts[pv]
        take = np.minimum(counts, _SEE_RAYS)
        # The rays (P,) of a pair are consecutive, and the pairs go by candidate: what is
        # per pair or per candidate is repeated to the rays (np.repeat), not gathered, and
        # the test runs one kept point at a time on (P,) columns: (P, k) gathers by candidate
        # made it ~3x slower (15 ms a scan with 1 cm of noise). The arithmetic is that of the
        # (P, k) form, value for value, so are the decisions. rays: per candidate.
        rays = np.bincount(pc, weights=take, minlength=len(vox)).astype(np.int64)  # (C,)
        j = np.arange(int(take.sum())) - np.repeat(np.cumsum(take) - take, take)
        pick = np.repeat(grid.starts[pv], take)
        pick += (j * np.repeat(counts, take)) // np.repeat(take, take)
        # Everything relative to the candidate's corner: the sensor, and the scan's points
        # (relative to their own voxel's corner) shifted by the step between the voxels.
        o = origin - grid.keys[vox] * size  # (C, 3)
        shift = _STEPS[pair % len(_STEPS)] * size  # (pairs, 3)
        # The kept points from the sensor, once per candidate: w (C, k) per axis, |w|^2.
        w = [raw[:, :, a].astype(np.float64) - o[:, a, None] for a in range(3)]
        w2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
        # Each ray (P,): its direction u and the length of the ray to its point.
        d = []
        for a in range(3):  # three axes
            da = np.take(grid.local[a], pick)
            da += np.repeat(shift[:, a], take)
            da -= np.repeat(o[:, a], rays)
            d.append(da)
        length = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        inv = 1.0 / np.maximum(length, 1e-12)
        u = [da * inv for da in d]
        before = length - np.repeat(np.maximum(_SEE_BEFORE * size, margin), rays)
        reach = _SEE_RADIUS * size
        radius2 = np.minimum(reach, _SEE_OFF * off) ** 2  # (C, k)
        through = np.zeros(len(j), bool)  # (P,): through one of the kept points so far
        along, tmp, hit = np.empty(len(j)), np.empty(len(j)), np.empty(len(j), bool)
        for q in range(raw.shape[1]):  # keep_points: kept point q of each candidate
            # q's distance along the ray, and whether the ray passes within radius of it.
            np.multiply(np.repeat(w[0][:, q], rays), u[0], out=along)
            along += np.multiply(np.repeat(w[1][:, q], rays), u[1], out=tmp)
            along += np.multiply(np.repeat(w[2][:, q], rays), u[2], out=tmp)
            np.subtract(np.repeat(w2[:, q], rays), np.multiply(along, along, out=tmp), out=tmp)
            np.less(tmp, np.repeat(radius2[:, q], rays), out=hit)
            hit &= along > 0.0
            hit &= along < before
            through |= hit
        return np.bincount(np.repeat(np.arange(len(vox)), rays)[through], minlength=len(vox)) > 0

    def _keep_recent(self, grid: _ScanGrid, slots: np.ndarray) -> None:
        """Ring buffer of the newest ``keep_points`` raw points per voxel (relative to corner).

        From each scan, up to ``keep_points`` of a voxel's points enter the ring, evenly spaced
        in input order (a lidar's input order runs along its rings, so they spread over the
        voxel rather than bunch at one end); they overwrite the oldest ones."""
        k = self.keep_points
        counts, starts = grid.counts, grid.starts
        # Voxels with k points or more (most) refill their whole ring: the pick meant for
        # position (head + j) % k lands there, so each ring row is written once, contiguous,
        # and its head stays put.
        full = np.flatnonzero(counts >= k)
        s = slots[full]
        j = np.arange(k) - self._raw_head[s][:, None]  # pick number of each ring position
        j[j < 0] += k
        # Evenly spaced picks among the voxel's points, not just its first ones.
        pick = starts[full, None] + (j * counts[full, None]) // k
        vals = np.empty((len(full), k, 3), np.float32)
        for a in range(3):  # three axes
            vals[:, :, a] = grid.local[a][pick]
        self._raw[s] = vals
        self._pts[s] = (self._keys[s] * self.size)[:, None, :] + vals
        self._raw_n[s] = k
        # Voxels with fewer points keep all of them (the even spacing picks every one) at
        # the ring positions after the head.
        part = np.flatnonzero(counts < k)
        s, take = slots[part], counts[part]
        head = self._raw_head[s]
        j = np.arange(k)
        use = j < take[:, None]
        pick = (starts[part, None] + j)[use]
        col = head[:, None] + j
        col[col >= k] -= k  # (head + j) % k, as head < k and j < k
        dest = (s[:, None] * k + col)[use]
        vals = np.empty((len(pick), 3), np.float32)
        for a in range(3):  # three axes
            vals[:, a] = grid.local[a][pick]
        self._raw.reshape(-1, 3)[dest] = vals
        self._pts.reshape(-1, 3)[dest] = (self._keys[s] * self.size)[np.nonzero(use)[0]] + vals
        head += take
        head[head >= k] -= k
        self._raw_head[s] = head
        self._raw_n[s] = np.minimum(self._raw_n[s] + take, k)

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
