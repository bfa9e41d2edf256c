"""One scan's voxels and their plane fits: what a merge adds to the store."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from supportnode.geometry.linalg import sym3_eigen_entries
from supportnode.geometry.voxels import OUTER_INDEX, argsort_keys, voxelize
from supportnode.kernels.scanvoxels import scan_voxels
from supportnode.map.state import StoreState

# The noise floor of a scan: this percentile of its dense voxels' own estimates (see
# _plane_noise).
_NOISE_PERCENTILE = 90.0


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


class ScanVoxelizer(StoreState):
    """Mixin of `VoxelMap`: a scan's voxels in scratch buffers kept across scans."""

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
        # The keys' extremes are the extreme coordinates' keys (x / size and its floor are
        # monotonic in x): no (N,) pass of keys unless the numpy path below needs them.
        lo = np.floor(np.array([float(c.min()) for c in cols]) / size)
        hi = np.floor(np.array([float(c.max()) for c in cols]) / size)
        far = max(np.abs(lo).max(), np.abs(hi).max()) >= 2**40
        dims = (hi - lo + 1.0) if not far else np.full(3, np.inf)
        if float(np.prod(dims)) >= 2.0**53:  # linear keys not exact in float64
            grid = voxelize(np.stack(cols, axis=1), np.full(3, size))  # raises when too far
            moments = np.concatenate([grid.sums, grid.outer], axis=1)
            return _ScanGrid(grid.keys, grid.counts, grid.starts, moments, grid.local)
        if float(np.prod(dims)) <= max(8 * n, 1 << 20):
            # Few keys in the box (the usual case): compiled, one pass over the points, a
            # mark table of the box's keys (the same voxels, offsets and sums as below).
            keys, voxel, counts, moments, local = scan_voxels(
                cols, size, lo, dims, self._scan_scratch(n, int(np.prod(dims)))
            )
            return _ScanGrid(keys, counts, None, moments, local, voxel)
        # Float keys, then offsets from the corner, in buffers kept across scans.
        kcols = []
        for a, c in enumerate(cols):  # three axes
            kc = np.divide(c, size, out=self._buffer(f"key{a}", n, np.float64))
            kcols.append(np.floor(kc, out=kc))
        return self._voxelize_large(cols, kcols, lo, dims)

    def _voxelize_large(
        self, cols: list[np.ndarray], kcols: list[np.ndarray], lo: np.ndarray, dims: np.ndarray
    ) -> _ScanGrid:
        """`_voxelize` of a scan whose box holds more keys than the compiled pass's table
        takes, by numpy: cols (N,) x, y, z columns, kcols their float voxel keys (overwritten
        with the offsets from the corners), lo (3,) the lowest key, dims (3,) the box in
        voxels (float). One function of ~70 lines, as `voxelize` is: each (N,) buffer is
        reused in place the moment it is spent."""
        size = self.size
        n = len(cols[0])
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

    def _scan_scratch(
        self, n: int, top: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The compiled voxelizing's scratch (`kernels.scanvoxels.scan_voxels`), kept."""
        return (
            self._buffer("mark", top, np.bool_),
            self._buffer("rank", top, np.int64),
            self._buffer("lin", n, np.int64),
            self._buffer("local", 3 * n, np.float64).reshape(3, n),
        )

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
