"""Voxel grids: integer keys, point-to-voxel grouping, per-voxel moments and neighbour lookup.

Moments are kept relative to each voxel's corner so that sums of squares stay precise far from
the origin and can be merged scan after scan (the node's map does exactly that).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from supportnode.errors import InputError

# Order of the six unique entries of a symmetric 3x3 second moment.
OUTER_INDEX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def argsort_keys(keys: np.ndarray, top: int | None = None) -> np.ndarray:
    """Stable argsort of non-negative (N,) integer keys; ``top``: their maximum, if known.

    LSD radix sort in 16-bit digits: numpy's stable sort is a radix sort for 16-bit types,
    several times faster than a comparison sort of int64 on millions of keys."""
    keys = np.asarray(keys)
    if top is None:
        if len(keys) and int(keys.min()) < 0:
            return np.argsort(keys, kind="stable")
        top = int(keys.max()) if len(keys) else 0
    if top >= 2**48:
        return np.argsort(keys, kind="stable")
    order = np.argsort((keys & 0xFFFF).astype(np.uint16), kind="stable")
    shift = 16
    while top >> shift:
        digit = ((keys[order] >> shift) & 0xFFFF).astype(np.uint16)
        order = order[np.argsort(digit, kind="stable")]
        shift += 16
    return order


def _argsort_runs(keys: np.ndarray, top: int) -> np.ndarray:
    """:func:`argsort_keys` of (N,) keys in ``0..top``, the same permutation, sorting runs of
    equal consecutive keys rather than keys: a map's points come grouped by its own (finer)
    voxels, a few runs per voxel, and a run's points stay in order in a stable sort."""
    n = len(keys)
    new = np.empty(n, dtype=bool)
    new[:1] = True
    np.not_equal(keys[1:], keys[:-1], out=new[1:])
    first = np.flatnonzero(new)
    if len(first) > n // 2:  # runs too short to pay off
        return argsort_keys(keys, top=top)
    by_run = argsort_keys(keys[first], top=top)
    length = np.diff(np.append(first, n))[by_run]
    # Run r of the sorted runs covers sorted positions [at_r, at_r + length_r) and holds
    # points first_r ... first_r + length_r - 1.
    shift = first[by_run] - (np.cumsum(length) - length)
    return np.repeat(shift, length) + np.arange(n)


@dataclass
class KeyIndex:
    """Sorted linear keys of a set of voxels, for vectorised lookup of (neighbour) keys."""

    origin: np.ndarray  # (3,) int64: key of linear index 0 (padded by one voxel on each side)
    dims: np.ndarray  # (3,) int64: padded extent, so key +- 1 never wraps
    sorted_lin: np.ndarray  # (M,) int64 ascending
    order: np.ndarray  # (M,) int64: voxel index of each sorted entry
    # (prod(dims),) int32 voxel index by linear key, -1 where empty; None for a sparse extent
    table: np.ndarray | None = None
    lin_of: np.ndarray | None = None  # (M,) int64 linear key of each voxel, in input order

    @classmethod
    def build(cls, keys: np.ndarray) -> KeyIndex:
        """Index (M, 3) int64 keys."""
        if len(keys) == 0:
            z = np.zeros(3, np.int64)
            return cls(z, np.ones(3, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
        # Column by column: numpy reduces (M, 3) along axis 0 an order of magnitude slower.
        origin = np.array([keys[:, a].min() for a in range(3)], dtype=np.int64) - 1
        dims = np.array([keys[:, a].max() for a in range(3)], dtype=np.int64) - origin + 2
        cells = float(np.prod(dims.astype(np.float64)))
        if cells >= 2.0**62:
            raise InputError("voxel grid too large to index (extent / voxel size overflows)")
        lin = cls._linear(keys, origin, dims)
        order = np.argsort(lin, kind="stable")
        table = None
        if cells <= max(1 << 18, 32 * len(keys)):
            # A dense extent (a room at 0.1 m is ~1e5 cells): direct lookup, no binary search.
            table = np.full(int(cells), -1, dtype=np.int32)
            table[lin[order[::-1]]] = order[::-1]  # duplicate keys: the first voxel wins
        return cls(origin, dims, lin[order], order, table, lin)

    @staticmethod
    def _linear(keys: np.ndarray, origin: np.ndarray, dims: np.ndarray) -> np.ndarray:
        k = keys - origin
        return (k[:, 0] * dims[1] + k[:, 1]) * dims[2] + k[:, 2]

    def find(self, keys: np.ndarray) -> np.ndarray:
        """Voxel index of each (Q, 3) key, -1 where absent."""
        if len(self.sorted_lin) == 0 or len(keys) == 0:
            return np.full(len(keys), -1, np.int64)
        k = [keys[:, a] - self.origin[a] for a in range(3)]
        inside = (k[0] >= 0) & (k[0] < self.dims[0])
        for a in (1, 2):
            inside &= (k[a] >= 0) & (k[a] < self.dims[a])
        lin = (k[0] * self.dims[1] + k[1]) * self.dims[2] + k[2]
        if self.table is not None:
            return np.where(inside, self.table[np.where(inside, lin, 0)], -1).astype(np.int64)
        pos = np.searchsorted(self.sorted_lin, lin)
        pos = np.minimum(pos, len(self.sorted_lin) - 1)
        hit = inside & (self.sorted_lin[pos] == lin)
        return np.where(hit, self.order[pos], -1)

    def neighbours(self, voxels: np.ndarray, offset: np.ndarray, keys: np.ndarray) -> np.ndarray:
        """Index of the voxel at ``keys[voxels] + offset`` for (Q,) indexed voxels, -1 where
        absent. keys: the (M, 3) keys given to ``build``.

        With a dense table and |offset| <= 1 on every axis: one add and one gather (the
        one-voxel padding keeps every such neighbour inside the table); else `find`."""
        off = np.asarray(offset, dtype=np.int64)
        if self.table is not None and self.lin_of is not None and np.abs(off).max() <= 1:
            step = (off[0] * self.dims[1] + off[1]) * self.dims[2] + off[2]
            return self.table[self.lin_of[voxels] + step].astype(np.int64)
        return self.find(keys[voxels] + off)

    def neighbours_many(
        self, voxels: np.ndarray, offsets: npt.ArrayLike, keys: np.ndarray
    ) -> np.ndarray:
        """:meth:`neighbours` of the (Q,) ``voxels`` at each of (K, 3) ``offsets`` in one
        vectorised lookup: (K, Q) int64, -1 where absent."""
        off = np.asarray(offsets, dtype=np.int64).reshape(-1, 3)
        voxels = np.asarray(voxels)
        if len(off) == 0:
            return np.zeros((0, len(voxels)), np.int64)
        if self.table is None or self.lin_of is None:
            shifted = keys[voxels][None, :, :] + off[:, None, :]
            return self.find(shifted.reshape(-1, 3)).reshape(len(off), len(voxels))
        step = (off[:, 0] * self.dims[1] + off[:, 1]) * self.dims[2] + off[:, 2]
        lin = self.lin_of[voxels][None, :] + step[:, None]
        # The one-voxel padding keeps every key within one voxel inside the table; beyond,
        # a key past the extent on an axis would wrap into another row: absent (as `find`).
        inside = None
        for a in np.flatnonzero(np.abs(off).max(axis=0) > 1):
            k = (keys[voxels, a] - self.origin[a])[None, :] + off[:, a, None]
            ok = (k >= 0) & (k < self.dims[a])
            inside = ok if inside is None else inside & ok
        if inside is None:
            return self.table[lin].astype(np.int64)
        return np.where(inside, self.table[np.where(inside, lin, 0)], -1).astype(np.int64)

    def neighbour_pairs(
        self, keys: np.ndarray, offsets: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pairs (i, j) of indexed voxels with keys[j] == keys[i] + offset for any offset.

        keys: (M, 3) keys of the indexed voxels (same order as given to ``build``).
        offsets: (K, 3) int64. Returns two (E,) int64 arrays, offset by offset, i ascending
        within each.
        """
        j = self.neighbours_many(np.arange(len(keys)), offsets, keys).ravel()
        hit = np.flatnonzero(j >= 0)
        if len(keys) == 0:
            return hit, hit.copy()
        return hit % len(keys), j[hit]


class Labelled(NamedTuple):
    """The labelled points (label >= 0) of grid-order labels (see `VoxelGrid.labelled`).

    at: (K,) int64 their positions, ascending; vox: (K,) int64 the voxel of each; per: (M,)
    int64 labelled points per voxel; last: (M,) int64 the label of each voxel's last
    labelled point, -1 for none."""

    at: np.ndarray
    vox: np.ndarray
    per: np.ndarray
    last: np.ndarray


@dataclass
class VoxelGrid:
    """Points grouped into voxels, with per-voxel moments.

    keys: (M, 3) int64 voxel coordinates, in ascending linear-key order.
    counts: (M,) int64 points per voxel.
    point_voxel: (N,) int64 voxel index of each input point.
    order: (N,) int64 point indices sorted by voxel; voxel v holds
        ``order[starts[v] : starts[v] + counts[v]]`` (for per-voxel reductions with reduceat).
    local: three (N,) float64 arrays, x, y, z of the points in ``order`` relative to their
        voxel's corner, metres (contiguous, for later per-voxel reductions without gathers).
    sums: (M, 3) float64 sum of (p - corner) over the voxel's points, metres.
    outer: (M, 6) float64 sum of products of (p - corner), entries in ``OUTER_INDEX`` order.
    """

    size: np.ndarray
    keys: np.ndarray
    counts: np.ndarray
    point_voxel: np.ndarray
    sums: np.ndarray
    outer: np.ndarray
    order: np.ndarray
    starts: np.ndarray
    local: list[np.ndarray]
    _position_voxel: np.ndarray | None = field(default=None, init=False, repr=False)

    def voxel_at(self, positions: np.ndarray) -> np.ndarray:
        """(K,) int64 voxel of each of the grid-order ``positions`` (K,) (indices into
        ``order`` and ``local``). A gather from a table built once per grid: the
        searchsorted over ``starts`` it replaces took ~0.6 ms a call on a depth image."""
        if self._position_voxel is None:
            self._position_voxel = np.repeat(np.arange(len(self.counts)), self.counts)
        return self._position_voxel[positions]

    def labelled(self, labels: np.ndarray) -> Labelled:
        """The points of (N,) grid-order ``labels`` that are >= 0, in one compiled pass: what
        ``flatnonzero(labels >= 0)``, ``voxel_at`` of it and per-voxel counts give."""
        from supportnode.kernels.runs import labelled  # numba only when used

        return Labelled(*labelled(labels, self.starts, self.counts))

    @property
    def corners(self) -> np.ndarray:
        """(M, 3) float64 minimum corner of each voxel, metres."""
        return self.keys * self.size

    def means(self) -> np.ndarray:
        """(M, 3) float64 centroid of each voxel's points, metres."""
        return self.corners + self.sums / self.counts[:, None]

    def covariances(self) -> np.ndarray:
        """(M, 3, 3) float64 population covariance of each voxel's points, m^2."""
        entries = self.covariance_entries()
        cov = np.empty((len(self.counts), 3, 3))
        for v, (a, b) in zip(entries, OUTER_INDEX, strict=True):
            cov[:, a, b] = v
            cov[:, b, a] = v
        return cov

    def covariance_entries(self, idx: np.ndarray | None = None) -> list[np.ndarray]:
        """The six distinct entries of :meth:`covariances` of the voxels ``idx`` (all when
        None), as (len(idx),) float64 columns in ``OUTER_INDEX`` order, m^2 (for
        ``linalg.sym3_eigen_entries``; the same values without the (M, 3, 3) stack)."""
        sums, outer, counts = self.sums, self.outer, self.counts
        if idx is not None:
            sums, outer, counts = sums[idx], outer[idx], counts[idx]
        c = counts.astype(np.float64)
        mean = [sums[:, a] / c for a in range(3)]
        return [outer[:, col] / c - mean[a] * mean[b] for col, (a, b) in enumerate(OUTER_INDEX)]


def voxelize(points: np.ndarray, size: np.ndarray | tuple[float, float, float]) -> VoxelGrid:
    """Group (N, 3) finite points into voxels of ``size`` (3,) metres and accumulate moments.

    Compiled (`kernels.voxelgrid`) when the points' box holds few possible keys, the usual
    case; otherwise `_voxelize_numpy`, which sorts. Both give the same bits."""
    pts = np.asarray(points, dtype=np.float64)
    size = np.asarray(size, dtype=np.float64).reshape(3)
    n = len(pts)
    if n == 0 or pts.ndim != 2 or pts.shape[1] != 3:
        return _voxelize_numpy(pts, size)
    from supportnode.kernels.voxelgrid import key_range, voxel_grid

    lo, hi, finite = key_range(pts, size)
    if not finite:
        raise InputError("points must be finite (and well inside float64's range) to voxelize")
    origin, dims = _box(lo, hi)
    top = int(np.prod(dims)) - 1
    if top >= max(8 * n, 1 << 20):
        return _voxelize_numpy(pts, size)
    vkeys, counts, starts, order, point_voxel, srt, sums, outer = voxel_grid(
        pts, size, origin, dims
    )
    return VoxelGrid(size, vkeys, counts, point_voxel, sums, outer, order, starts, list(srt))


def _box(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The keys' origin and extent (3,) int64 from their floored minima and maxima (3,)."""
    if max(np.abs(lo).max(), np.abs(hi).max()) >= 2**40:
        raise InputError("points too far from the origin for this voxel size (|key| >= 2^40)")
    origin = lo.astype(np.int64)
    dims = (hi - lo).astype(np.int64) + 1
    if float(np.prod(dims.astype(np.float64))) >= 2.0**62:
        raise InputError("voxel grid too large to index (extent / voxel size overflows)")
    return origin, dims


def _voxelize_numpy(points: np.ndarray, size: np.ndarray) -> VoxelGrid:
    """`voxelize` in numpy (the sorting path for sparse boxes, and the compiled one's
    reference).

    One function of ~80 lines on purpose: its (N,) buffers are dropped (``del``) or reused
    the moment they are spent, and its time follows its peak memory (fresh pages fault);
    split into steps, each buffer would live until its step returned."""
    pts = np.asarray(points, dtype=np.float64)
    size = np.asarray(size, dtype=np.float64).reshape(3)
    n = len(pts)
    if n == 0:
        e = np.zeros(0, np.int64)
        f = np.zeros(0)
        keys = np.zeros((0, 3), np.int64)
        return VoxelGrid(size, keys, e, e, np.zeros((0, 3)), np.zeros((0, 6)), e, e, [f, f, f])
    # Column by column, straight from the (strided) input columns: no (N, 3) copy. Every
    # (N,) temporary is done in place or reused: fresh pages cost more than the arithmetic
    # on them (a page fault each), so the peak memory of this step sets much of its time.
    kcols = []
    for a in range(3):
        q = pts[:, a] / size[a]
        kcols.append(np.floor(q, out=q))
    origin, dims = _box(np.array([c.min() for c in kcols]), np.array([c.max() for c in kcols]))
    # lin = ((k0 * d1) + k1) * d2 + k2 of the origin-relative keys k, in one buffer.
    lin = kcols[0].astype(np.int64)
    lin -= origin[0]
    k = np.empty(n, dtype=np.int64)
    for a in (1, 2):
        lin *= dims[a]
        k[...] = kcols[a]  # integral floats: exact, as astype
        k -= origin[a]
        lin += k
    del k
    # Offsets from the voxel corner per point, in place of the float keys (kcols holds each
    # point's key as a float: the same products as vkeys * size), gathered once sorted.
    for a in range(3):
        kcols[a] *= size[a]
        np.subtract(pts[:, a], kcols[a], out=kcols[a])
    top = int(np.prod(dims)) - 1
    if top < max(8 * n, 1 << 20):
        # Few possible keys (the usual case: a room is ~1e5 voxels): a counting pass ranks
        # the occupied keys, and sorting the points by that rank (< 2^16 voxels: one 16-bit
        # radix pass) replaces the sort of the linear keys; the rank is each point's voxel.
        occupied = np.bincount(lin, minlength=top + 1)
        lin_of_voxel = np.flatnonzero(occupied)
        counts = occupied[lin_of_voxel]
        rank = occupied  # read at occupied keys only: its other entries may stay
        rank[lin_of_voxel] = np.arange(len(lin_of_voxel))
        point_voxel = np.take(rank, lin)
        del rank, occupied, lin
        order = _argsort_runs(point_voxel, top=len(lin_of_voxel) - 1)
        starts = np.cumsum(counts) - counts
    else:
        # Sorting is the one O(N log N) step; everything after it is contiguous reductions.
        order = argsort_keys(lin, top=top)
        lin_sorted = np.take(lin, order)
        del lin
        new = np.empty(n, dtype=bool)
        new[0] = True
        np.not_equal(lin_sorted[1:], lin_sorted[:-1], out=new[1:])
        starts = np.flatnonzero(new)
        counts = np.diff(np.append(starts, n))
        point_voxel = np.empty(n, dtype=np.int64)
        point_voxel[order] = np.cumsum(new) - 1
        lin_of_voxel = lin_sorted[starts]
        del lin_sorted, new
    rem, kz = np.divmod(lin_of_voxel, dims[2])
    kx, ky = np.divmod(rem, dims[1])
    vkeys = np.stack([kx, ky, kz], axis=1) + origin
    # np.take gathers faster than fancy indexing; the gathers are the costliest step here.
    # Each column's unsorted offsets are freed once gathered: their pages serve the next.
    local = [np.take(kcols.pop(0), order) for _ in range(3)]
    sums = np.stack([np.add.reduceat(c, starts) for c in local], axis=1)
    outer = np.empty((len(starts), 6))
    prod = np.empty(n)  # one buffer for the six products
    for col, (a, b) in enumerate(OUTER_INDEX):
        outer[:, col] = np.add.reduceat(np.multiply(local[a], local[b], out=prod), starts)
    return VoxelGrid(size, vkeys, counts, point_voxel, sums, outer, order, starts, local)


def horizontal_offsets(connectivity: int) -> np.ndarray:
    """Forward (half) neighbour offsets within one height layer: (K, 3) int64."""
    if connectivity == 4:
        return np.array([[1, 0, 0], [0, 1, 0]], dtype=np.int64)
    if connectivity == 8:
        return np.array([[1, 0, 0], [0, 1, 0], [1, 1, 0], [1, -1, 0]], dtype=np.int64)
    raise InputError(f"connectivity must be 4 or 8, got {connectivity}")


def layered_offsets(connectivity: int) -> np.ndarray:
    """Forward (half) neighbour offsets in xy (4 or 8) across layers dz in {-1, 0, 1}, plus the
    voxel directly above: (K, 3) int64. Together with their negations they cover every neighbour."""
    planar = horizontal_offsets(connectivity)
    out = [planar + [0, 0, dz] for dz in (-1, 0, 1)]
    out.append(np.array([[0, 0, 1]], dtype=np.int64))
    return np.concatenate(out)
