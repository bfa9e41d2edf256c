"""Stable ids across scans for surfaces and clusters, by footprint overlap.

Every detection is a footprint (a set of cells on a fixed 2-D grid, map frame) plus a height.
A detection continues the track whose last footprint it overlaps most (intersection over union
of cells), at a similar height; the assignment is optimal over all pairs (Hungarian,
``scipy.optimize.linear_sum_assignment``), so it does not depend on the order of detections.
Unmatched detections start new tracks (ids increase monotonically, never reused); a track
unmatched for ``max_misses`` consecutive updates is reported gone and forgotten.

Pure: no sockets, no printing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from supportnode.errors import InputError

# Cell coordinates are packed around an offset of 2^30 (|ix|, |iy| < 2^30 cells: 21,000 km
# at 2 cm) into 31 + 32 bits, so packed keys sort like (ix, iy) and never overflow int64.
_CELL_OFFSET = 1 << 30


def _pack(ix: np.ndarray, iy: np.ndarray) -> np.ndarray:
    return ((ix + _CELL_OFFSET) << 32) | (iy + _CELL_OFFSET)


def pack_cells(cells: np.ndarray) -> np.ndarray:
    """(C, 2) int cells (ix, iy) -> (C,) sorted unique int64, in (ix, iy) order."""
    c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    packed = _pack(c[:, 0], c[:, 1])
    if len(packed) > 1 and (packed[1:] > packed[:-1]).all():
        return packed  # already sorted and distinct: skip the sort
    return np.unique(packed)


def unpack_cells(packed: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pack_cells`: (C,) int64 -> (C, 2) int64."""
    p = np.asarray(packed, dtype=np.int64)
    return np.stack([(p >> 32) - _CELL_OFFSET, (p & 0xFFFFFFFF) - _CELL_OFFSET], axis=1)


def polygon_cells(polygon: np.ndarray, cell_size: float) -> np.ndarray:
    """:func:`polygon_cells_packed` as (C, 2) int64 cells, sorted like ``np.unique(axis=0)``."""
    return unpack_cells(polygon_cells_packed(polygon, cell_size))


def polygon_cells_packed(polygon: np.ndarray, cell_size: float) -> np.ndarray:
    """Packed cells (C,) (:func:`pack_cells`) of a grid of ``cell_size`` metres whose centres
    lie inside a convex counter-clockwise (K, 2) polygon (e.g. ``Cluster.footprint``), plus
    the cells its outline runs through and the cell of its centroid, so slivers and tiny
    objects still have a footprint. Sorted like ``np.unique(axis=0)``."""
    return polygons_cells_packed([polygon], cell_size)[0]


def polygons_cells_packed(polygons: list[np.ndarray], cell_size: float) -> list[np.ndarray]:
    """:func:`polygon_cells_packed` of each (K_i, 2) polygon: (C_i,) packed cells each, in the
    order given, computed for all polygons in one vectorised pass (a scan has tens of
    clusters; a loop over them cost more than the cells).

    Column by column: in a counter-clockwise polygon the edges running towards +x bound the
    inside from below and those running towards -x from above, so each grid column's cells are
    one interval. Cost grows with the columns and the cells returned, not with the bounding
    box (a room-sized wall hull at 2 cm would be 50,000 point-in-polygon tests per edge)."""
    polys = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in polygons]
    out = [np.zeros(0, np.int64) for _ in polys]
    live = [i for i, p in enumerate(polys) if len(p)]
    if not live:
        return out
    ps = [polys[i] for i in live]
    nv = np.array([len(p) for p in ps])
    a = np.concatenate(ps)
    vid = np.repeat(np.arange(len(ps)), nv)  # polygon of each vertex / edge
    first = np.cumsum(nv) - nv
    nxt = np.arange(len(a)) + 1
    last = first + nv - 1
    nxt[last] = first  # each polygon closes on its first vertex
    d = a[nxt] - a
    lo = np.stack([np.minimum.reduceat(a[:, k], first) for k in range(2)], axis=1)
    hi = np.stack([np.maximum.reduceat(a[:, k], first) for k in range(2)], axis=1)
    lo = np.floor(lo / cell_size).astype(np.int64)
    hi = np.floor(hi / cell_size).astype(np.int64)
    width = hi[:, 0] - lo[:, 0] + 1
    height = hi[:, 1] - lo[:, 1] + 1
    # Every column of every polygon.
    cpid = np.repeat(np.arange(len(ps)), width)
    cols = np.arange(len(cpid)) - np.repeat(np.cumsum(width) - width, width) + lo[cpid, 0]
    y_lo = lo[cpid, 1].copy()
    y_hi = hi[cpid, 1].copy()
    xc = (cols + 0.5) * cell_size
    # (edge, column) pairs of the same polygon, grouped by column; polygons of fewer than three
    # vertices have no inside test (their cells are the outline's).
    ne = np.where(nv >= 3, nv, 0)[cpid]
    pcol = np.repeat(np.arange(len(cpid)), ne)
    pe = np.arange(len(pcol)) - np.repeat(np.cumsum(ne) - ne, ne) + first[cpid[pcol]]
    if len(pcol):
        dx, dy = d[pe, 0], d[pe, 1]
        x = xc[pcol]
        with np.errstate(divide="ignore", invalid="ignore"):
            # The same test as "cross product >= -1e-12" for every edge, solved for y.
            line = a[pe, 1] + dy / dx * (x - a[pe, 0])
            line -= 1e-12 / dx
        has = np.flatnonzero(ne > 0)
        starts = (np.cumsum(ne) - ne)[has]
        up = dx > 0
        low = np.maximum.reduceat(np.where(up, line, -np.inf), starts)
        top = np.minimum.reduceat(np.where(dx < 0, line, np.inf), starts)
        any_up = np.logical_or.reduceat(up, starts)
        any_down = np.logical_or.reduceat(dx < 0, starts)
        y_lo[has] = np.where(
            any_up,
            np.maximum(y_lo[has], np.ceil(low / cell_size - 0.5).astype(np.int64)),
            y_lo[has],
        )
        y_hi[has] = np.where(
            any_down,
            np.minimum(y_hi[has], np.floor(top / cell_size - 0.5).astype(np.int64)),
            y_hi[has],
        )
        vert = dx == 0
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = a[pe, 0] + 1e-12 / dy
        fail = vert & (((dy > 0) & ~(x <= bound)) | ((dy < 0) & ~(x >= bound)))
        drop = np.logical_or.reduceat(fail, starts)
        y_hi[has] = np.where(drop, y_lo[has] - 1, y_hi[has])
    # Inside cells, as keys local to each polygon's bounding box: (ix - lo_x) * H + (iy - lo_y),
    # offset per polygon, so they sort like packed (ix, iy) within a polygon and by polygon.
    box = width * height
    base = np.cumsum(box) - box
    n = np.maximum(y_hi - y_lo + 1, 0)
    ccol = np.repeat(np.arange(len(cpid)), n)
    cy = np.arange(len(ccol)) - np.repeat(np.cumsum(n) - n, n) + y_lo[ccol]
    p_in = cpid[ccol]
    inside = base[p_in] + (cols[ccol] - lo[p_in, 0]) * height[p_in] + (cy - lo[p_in, 1])
    # The cells along the outline and of the centroid (see polygon_cells_packed).
    dd = np.where((nv > 1)[vid, None], d, 0.0)
    steps = np.maximum(np.ceil(np.hypot(dd[:, 0], dd[:, 1]) / (0.5 * cell_size)), 1)
    steps = steps.astype(np.int64)
    e = np.repeat(np.arange(len(a)), steps)
    t = (np.arange(len(e)) - np.repeat(np.cumsum(steps) - steps, steps)) / steps[e]
    edge = np.floor((a[e] + t[:, None] * dd[e]) / cell_size).astype(np.int64)
    sums = np.stack([np.add.reduceat(a[:, k], first) for k in range(2)], axis=1)
    own = np.floor(sums / nv[:, None] / cell_size).astype(np.int64)
    ep = np.concatenate([vid[e], np.arange(len(ps))])
    ec = np.concatenate([edge, own])
    extra = base[ep] + (ec[:, 0] - lo[ep, 0]) * height[ep] + (ec[:, 1] - lo[ep, 1])
    extra, first_of = np.unique(extra, return_index=True)
    pos = np.searchsorted(inside, extra)
    new = np.ones(len(extra), bool)
    if len(inside):
        new = ~((pos < len(inside)) & (inside[np.minimum(pos, len(inside) - 1)] == extra))
    inside_packed = _pack(cols[ccol], cy)
    extra_packed = _pack(ec[first_of[new], 0], ec[first_of[new], 1])
    packed = np.insert(inside_packed, pos[new], extra_packed)
    count = np.bincount(p_in, minlength=len(ps)) + np.bincount(ep[first_of[new]], minlength=len(ps))
    bounds = np.concatenate([[0], np.cumsum(count)])
    for k, i in enumerate(live):  # one slice per polygon
        out[i] = packed[bounds[k] : bounds[k + 1]]
    return out


def overlap_matrix(a: list[np.ndarray], b: list[np.ndarray]) -> np.ndarray:
    """Intersection-over-union of footprints: (len(a), len(b)) float64.

    a, b: lists of packed cell arrays (:func:`pack_cells`). Vectorised over all cells: one
    sort of the cells of ``b`` and a search of those of ``a``, no loop over pairs."""
    na, nb = len(a), len(b)
    iou = np.zeros((na, nb))
    if na == 0 or nb == 0:
        return iou
    size_a = np.array([len(x) for x in a])
    size_b = np.array([len(x) for x in b])
    ca, la = np.concatenate(a), np.repeat(np.arange(na), size_a)
    cb, lb = np.concatenate(b), np.repeat(np.arange(nb), size_b)
    order = np.argsort(cb, kind="stable")
    cb, lb = cb[order], lb[order]
    # A cell can belong to several footprints of b (stacked shelf boards): expand ranges.
    start = np.searchsorted(cb, ca, side="left")
    stop = np.searchsorted(cb, ca, side="right")
    n = stop - start
    rows = np.repeat(la, n)
    idx = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + np.repeat(start, n)
    inter = np.bincount(rows * nb + lb[idx], minlength=na * nb).reshape(na, nb).astype(float)
    union = size_a[:, None] + size_b[None, :] - inter
    np.divide(inter, union, out=iou, where=union > 0)
    return iou


@dataclass
class TrackUpdate:
    """Result of one :meth:`OverlapTracker.update`.

    ids: (D,) int64 stable id of each detection, in the order given.
    new: ids that started with this update. gone: ids dropped after too many misses.
    """

    ids: np.ndarray
    new: list[int] = field(default_factory=list)
    gone: list[int] = field(default_factory=list)


@dataclass
class _Track:
    id: int
    cells: np.ndarray  # packed, sorted
    height: float
    group: int
    misses: int = 0
    hits: int = 1


class OverlapTracker:
    """Persistent ids for footprints on a fixed grid.

    min_iou: smallest footprint IoU for a detection to continue a track.
    height_tolerance: largest height difference (metres) between a track and its detection.
    max_misses: consecutive updates a track may go unmatched before it is reported gone.
    Detections and tracks may carry a ``group`` (e.g. the stable id of the surface a cluster
    stands on); with ``match_groups`` only equal groups match.
    """

    def __init__(
        self,
        min_iou: float = 0.2,
        height_tolerance: float = 0.05,
        max_misses: int = 3,
        match_groups: bool = False,
    ) -> None:
        if not 0.0 < min_iou <= 1.0 or max_misses < 1 or height_tolerance < 0:
            raise InputError("need 0 < min_iou <= 1, max_misses >= 1, height_tolerance >= 0")
        self.min_iou = float(min_iou)
        self.height_tolerance = float(height_tolerance)
        self.max_misses = int(max_misses)
        self.match_groups = bool(match_groups)
        self._tracks: list[_Track] = []
        self._next_id = 0

    @property
    def tracks(self) -> dict[int, dict]:
        """Live tracks by id: packed cells, height, misses, hits (copies of small fields)."""
        return {
            t.id: {"cells": t.cells, "height": t.height, "misses": t.misses, "hits": t.hits}
            for t in self._tracks
        }

    def update(
        self,
        cells: list[np.ndarray],
        heights: np.ndarray,
        groups: np.ndarray | None = None,
    ) -> TrackUpdate:
        """Match one scan's detections to the tracks.

        cells: per detection, (C, 2) int footprint cells on the tracker's fixed grid.
        heights: (D,) float64 metres. groups: (D,) int or None.
        """
        heights = np.asarray(heights, dtype=np.float64).reshape(-1)
        if len(cells) != len(heights):
            raise InputError(f"{len(cells)} footprints but {len(heights)} heights")
        d = len(cells)
        grp = np.full(d, -1, np.int64) if groups is None else np.asarray(groups, np.int64)
        return self._update_packed([pack_cells(c) for c in cells], heights, grp)

    def _update_packed(
        self, packed: list[np.ndarray], heights: np.ndarray, grp: np.ndarray
    ) -> TrackUpdate:
        """`update` with footprints already packed (sorted unique (C,) int64 each)."""
        d = len(packed)
        tracks = self._tracks
        iou = overlap_matrix(packed, [t.cells for t in tracks])
        t_height = np.array([t.height for t in tracks])
        ok = iou >= self.min_iou
        if len(tracks):
            ok &= np.abs(heights[:, None] - t_height[None, :]) <= self.height_tolerance
            if self.match_groups:
                ok &= grp[:, None] == np.array([t.group for t in tracks])[None, :]
        # Hungarian on IoU; pairs below the gates cost more than leaving both unmatched.
        cost = np.where(ok, -iou, 1.0)
        rows, cols = linear_sum_assignment(cost) if d and len(tracks) else ([], [])
        ids = np.full(d, -1, np.int64)
        matched = np.zeros(len(tracks), bool)
        for r, c in zip(rows, cols, strict=True):  # at most min(D, T) pairs
            if ok[r, c]:
                t = tracks[c]
                ids[r] = t.id
                t.cells, t.height, t.group = packed[r], float(heights[r]), int(grp[r])
                t.misses, t.hits = 0, t.hits + 1
                matched[c] = True
        out = TrackUpdate(ids)
        for r in np.flatnonzero(ids < 0):  # new detections: a handful per scan
            t = _Track(self._next_id, packed[r], float(heights[r]), int(grp[r]))
            self._next_id += 1
            tracks.append(t)
            ids[r] = t.id
            out.new.append(t.id)
        keep = []
        for i, t in enumerate(tracks):
            if i < len(matched) and not matched[i]:
                t.misses += 1
                if t.misses >= self.max_misses:
                    out.gone.append(t.id)
                    continue
            keep.append(t)
        self._tracks = keep
        return out


class SurfaceTracker(OverlapTracker):
    """Stable ids for :class:`~supportnode.geometry.surfaces.Surface` lists (footprint cells on
    the detection grid ``Surface.cells``, height ``Surface.height``)."""

    def update_surfaces(self, surfaces: list) -> TrackUpdate:
        """surfaces: list of Surface (their ``cells`` must share one ``cell_size``)."""
        sizes = {tuple(s.cell_size) for s in surfaces}
        if len(sizes) > 1:
            raise InputError(f"surfaces on different grids: {sorted(sizes)}")
        return self.update([s.cells for s in surfaces], np.array([s.height for s in surfaces]))


class ClusterTracker(OverlapTracker):
    """Stable ids for :class:`~supportnode.geometry.objects.Cluster` lists: footprint polygons
    rasterised on a ``cell_size`` grid, height = bottom of the bounding box; ``group`` = the
    stable id of the surface under the cluster (-1 for none)."""

    def __init__(self, cell_size: float = 0.02, **kw) -> None:
        kw.setdefault("height_tolerance", 0.05)
        super().__init__(**kw)
        self.cell_size = float(cell_size)
        # Footprint bytes -> packed cells, of the previous update: clusters that did not
        # change (far away, or a static scene) are not rasterised again.
        self._cells: dict[bytes, np.ndarray] = {}

    def update_clusters(self, clusters: list, surface_ids: np.ndarray | None = None) -> TrackUpdate:
        """clusters: list of Cluster; surface_ids: (D,) stable surface id under each (-1 none)."""
        keys = [np.ascontiguousarray(c.footprint, dtype=np.float64).tobytes() for c in clusters]
        miss = [i for i, k in enumerate(keys) if k not in self._cells]
        fresh = polygons_cells_packed([clusters[i].footprint for i in miss], self.cell_size)
        cells = dict(zip((keys[i] for i in miss), fresh, strict=True))
        packed = [cells[k] if k in cells else self._cells[k] for k in keys]
        self._cells = dict(zip(keys, packed, strict=True))
        bottoms = np.array([float(c.bbox_min[2]) for c in clusters])
        grp = (
            np.full(len(clusters), -1, np.int64)
            if surface_ids is None
            else np.asarray(surface_ids, np.int64).reshape(-1)
        )
        if len(grp) != len(clusters):
            raise InputError(f"{len(clusters)} clusters but {len(grp)} surface ids")
        return self._update_packed(packed, bottoms, grp)
