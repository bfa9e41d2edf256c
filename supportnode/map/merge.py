"""Merging a scan's voxels into the store: moments, evidence and the kept points."""

from __future__ import annotations

import numpy as np

from supportnode.errors import InputError
from supportnode.kernels.places import fill_places, off_plane
from supportnode.map.keys import pack_keys
from supportnode.map.scan import ScanVoxelizer, _plane_fits, _plane_noise, _ScanGrid

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
# The 27 steps from a voxel to itself and its neighbours, x slowest.
_STEPS = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)


class Merging(ScanVoxelizer):
    """Mixin of `VoxelMap`: `_merge` and the kept points' policies."""

    def _merge_scan(
        self, points: np.ndarray, pose: np.ndarray, stamp: float, in_map_frame: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`merge`: the scan's (V,) slots and (V, 3) keys, and its box lo, hi (3,), m."""
        if self._pending is not None:
            self.settle()
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
        if self.params.clear_free_space and npts:
            # The rays' origin must have a key (see settle), checked before the map changes.
            pack_keys(np.floor(origin / self.size).astype(np.int64)[None])
        self._scans += 1
        self._stats["scans"] += 1
        self._stats["points_merged"] += npts
        slots, keys = self._merge(cols, float(stamp), origin)
        lo = np.array([c.min() for c in cols]) if npts else np.full(3, np.inf)
        hi = np.array([c.max() for c in cols]) if npts else np.full(3, -np.inf)
        self._pending = (cols, origin, float(stamp))
        return slots, keys, lo, hi

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
        if len(new):
            self._hash.insert(packed[new], slots[new])
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
        n = self._raw_n[slots]
        # The voxels whose points are needed by voxel (_by_voxel): those with free places
        # (renewed ones are among the candidates, added by _renew_changed).
        need = n < self.keep_points
        had = np.flatnonzero((n > 0) & (grid.counts >= 4))
        if len(had):
            grid = self._renew_changed(grid, packed, slots, had, need, origin)
        else:
            grid = self._by_voxel(grid, need)
        self._fill_places(grid, slots)

    def _renew_changed(
        self,
        grid: _ScanGrid,
        packed: np.ndarray,
        slots: np.ndarray,
        had: np.ndarray,
        need: np.ndarray,
        origin: np.ndarray,
    ) -> _ScanGrid:
        """Empty the kept points of the scan's voxels ``had`` (indices into ``slots``, voxels
        with kept points and >= 4 scan points) that this scan shows changed (see
        _keep_first); marks in ``need`` the voxels whose points that took; returns the grid
        with points by voxel."""
        moments = np.take(grid.moments, had, axis=0)
        count = grid.counts[had]
        seen, evals, normal, planar = _plane_fits(count, moments[:, :3], moments[:, 3:], self.size)
        # Only a plane says where the kept points should lie (not a line: one lidar ring).
        # Most voxels are planes: the tests below run on all (each voxel's result is its
        # own), and only the end keeps the planes, rather than gathering them first.
        s = slots[had]
        # |kept point . normal - mean . normal| per place (0: not filled), compiled.
        dist, most = off_plane(
            self._raw, s, self._raw_n, normal, np.einsum("ij,ij->i", seen, normal)
        )
        noise = _plane_noise(evals[:, 0], count, planar)
        tol = np.maximum(0.2 * self.size, 3.5 * noise)
        off = np.flatnonzero(planar & (most > tol))
        # The candidates' rays come from the scan's points in them and their neighbours.
        pairs = self._neighbour_pairs(grid, packed, had[off])
        need[pairs[1]] = True
        grid = self._by_voxel(grid, need)
        seen_through = self._seen_through(
            grid, had[off], pairs, self._raw[s[off]], dist[off], origin, 3.0 * noise[off]
        )
        renew = s[off[seen_through]]
        self._raw_n[renew] = 0
        self._stats["renewed"] += len(renew)
        return grid

    def _fill_places(self, grid: _ScanGrid, slots: np.ndarray) -> None:
        """Fill each voxel's free kept-point places with evenly spaced picks of the scan's
        points in it (grid: points by voxel; compiled: `kernels.places`)."""
        assert grid.starts is not None  # _by_voxel sorted the voxels' points
        filled = fill_places(
            slots,
            grid.counts,
            grid.starts,
            grid.local,
            self._keys,
            self.size,
            self._raw,
            self._pts,
            self._raw_n,
        )
        self.version += int(filled > 0)  # new voxels, renewed ones, or ones not yet full

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
        per voxel. One function of ~75 lines: a dozen (P,) columns are built for the loop at
        its end and consumed there; split, each step would hand them all on."""
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
        assert grid.starts is not None  # the candidates' points are sorted by voxel
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
        assert starts is not None  # the caller sorted the voxels' points
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
