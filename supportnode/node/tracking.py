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
from supportnode.kernels.overlap import shared_cells

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
    e = _Edges.of([polys[i] for i in live], cell_size)
    cpid, cols, y_lo, y_hi = _column_spans(e, cell_size)
    # Inside cells, as keys local to each polygon's bounding box: (ix - lo_x) * H + (iy - lo_y),
    # offset per polygon, so they sort like packed (ix, iy) within a polygon and by polygon.
    box = e.width * e.height
    base = np.cumsum(box) - box
    n = np.maximum(y_hi - y_lo + 1, 0)
    ccol = np.repeat(np.arange(len(cpid)), n)
    cy = np.arange(len(ccol)) - np.repeat(np.cumsum(n) - n, n) + y_lo[ccol]
    p_in = cpid[ccol]
    inside = base[p_in] + (cols[ccol] - e.lo[p_in, 0]) * e.height[p_in] + (cy - e.lo[p_in, 1])
    ep, ec = _outline_cells(e, cell_size)
    extra = base[ep] + (ec[:, 0] - e.lo[ep, 0]) * e.height[ep] + (ec[:, 1] - e.lo[ep, 1])
    extra, first_of = np.unique(extra, return_index=True)
    pos = np.searchsorted(inside, extra)
    new = np.ones(len(extra), bool)
    if len(inside):
        new = ~((pos < len(inside)) & (inside[np.minimum(pos, len(inside) - 1)] == extra))
    inside_packed = _pack(cols[ccol], cy)
    extra_packed = _pack(ec[first_of[new], 0], ec[first_of[new], 1])
    packed = np.insert(inside_packed, pos[new], extra_packed)
    n_poly = len(e.nv)
    count = np.bincount(p_in, minlength=n_poly) + np.bincount(ep[first_of[new]], minlength=n_poly)
    bounds = np.concatenate([[0], np.cumsum(count)])
    for k, i in enumerate(live):  # one slice per polygon
        out[i] = packed[bounds[k] : bounds[k + 1]]
    return out


@dataclass
class _Edges:
    """The polygons of :func:`polygons_cells_packed` as one edge list: vertices a (V, 2) m,
    edge vectors d (V, 2) (each vertex to the next, the last closing on the first), polygon of
    each vertex vid (V,), first vertex (P,) and vertex count nv (P,) per polygon, and each
    polygon's bounding box in cells lo, hi (P, 2), width, height (P,)."""

    a: np.ndarray
    d: np.ndarray
    vid: np.ndarray
    first: np.ndarray
    nv: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    width: np.ndarray
    height: np.ndarray

    @classmethod
    def of(cls, polys: list[np.ndarray], cell_size: float) -> _Edges:
        nv = np.array([len(p) for p in polys])
        a = np.concatenate(polys)
        vid = np.repeat(np.arange(len(polys)), nv)
        first = np.cumsum(nv) - nv
        nxt = np.arange(len(a)) + 1
        nxt[first + nv - 1] = first  # each polygon closes on its first vertex
        lo = np.stack([np.minimum.reduceat(a[:, k], first) for k in range(2)], axis=1)
        hi = np.stack([np.maximum.reduceat(a[:, k], first) for k in range(2)], axis=1)
        lo = np.floor(lo / cell_size).astype(np.int64)
        hi = np.floor(hi / cell_size).astype(np.int64)
        width, height = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
        return cls(a, a[nxt] - a, vid, first, nv, lo, hi, width, height)


def _column_spans(
    e: _Edges, cell_size: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every grid column of every polygon: its polygon (C,), column index (C,) and the first
    and last inside cell row (C,) (last < first: none), from the edges that bound the column
    from below (running towards +x) and above (towards -x)."""
    cpid = np.repeat(np.arange(len(e.nv)), e.width)
    cols = np.arange(len(cpid)) - np.repeat(np.cumsum(e.width) - e.width, e.width)
    cols += e.lo[cpid, 0]
    y_lo = e.lo[cpid, 1].copy()
    y_hi = e.hi[cpid, 1].copy()
    # (edge, column) pairs of the same polygon, grouped by column; polygons of fewer than three
    # vertices have no inside test (their cells are the outline's).
    ne = np.where(e.nv >= 3, e.nv, 0)[cpid]
    pcol = np.repeat(np.arange(len(cpid)), ne)
    if len(pcol) == 0:
        return cpid, cols, y_lo, y_hi
    pe = np.arange(len(pcol)) - np.repeat(np.cumsum(ne) - ne, ne) + e.first[cpid[pcol]]
    dx, dy = e.d[pe, 0], e.d[pe, 1]
    x = ((cols + 0.5) * cell_size)[pcol]
    with np.errstate(divide="ignore", invalid="ignore"):
        # The same test as "cross product >= -1e-12" for every edge, solved for y.
        line = e.a[pe, 1] + dy / dx * (x - e.a[pe, 0])
        line -= 1e-12 / dx
        bound = e.a[pe, 0] + 1e-12 / dy
    has = np.flatnonzero(ne > 0)
    starts = (np.cumsum(ne) - ne)[has]
    up = dx > 0
    low = np.maximum.reduceat(np.where(up, line, -np.inf), starts)
    top = np.minimum.reduceat(np.where(dx < 0, line, np.inf), starts)
    any_up = np.logical_or.reduceat(up, starts)
    any_down = np.logical_or.reduceat(dx < 0, starts)
    raised = np.maximum(y_lo[has], np.ceil(low / cell_size - 0.5).astype(np.int64))
    y_lo[has] = np.where(any_up, raised, y_lo[has])
    lowered = np.minimum(y_hi[has], np.floor(top / cell_size - 0.5).astype(np.int64))
    y_hi[has] = np.where(any_down, lowered, y_hi[has])
    fail = (dx == 0) & (((dy > 0) & ~(x <= bound)) | ((dy < 0) & ~(x >= bound)))
    drop = np.logical_or.reduceat(fail, starts)
    y_hi[has] = np.where(drop, y_lo[has] - 1, y_hi[has])
    return cpid, cols, y_lo, y_hi


def _outline_cells(e: _Edges, cell_size: float) -> tuple[np.ndarray, np.ndarray]:
    """The cells along each polygon's outline (sampled every half cell) and of its centroid
    (see polygon_cells_packed): polygon (K,) and cell (K, 2) int64, with repeats."""
    dd = np.where((e.nv > 1)[e.vid, None], e.d, 0.0)
    steps = np.maximum(np.ceil(np.hypot(dd[:, 0], dd[:, 1]) / (0.5 * cell_size)), 1)
    steps = steps.astype(np.int64)
    k = np.repeat(np.arange(len(e.a)), steps)
    t = (np.arange(len(k)) - np.repeat(np.cumsum(steps) - steps, steps)) / steps[k]
    edge = np.floor((e.a[k] + t[:, None] * dd[k]) / cell_size).astype(np.int64)
    sums = np.stack([np.add.reduceat(e.a[:, j], e.first) for j in range(2)], axis=1)
    own = np.floor(sums / e.nv[:, None] / cell_size).astype(np.int64)
    ep = np.concatenate([e.vid[k], np.arange(len(e.nv))])
    return ep, np.concatenate([edge, own])


def overlap_matrix(a: list[np.ndarray], b: list[np.ndarray]) -> np.ndarray:
    """Intersection-over-union of footprints: (len(a), len(b)) float64.

    a, b: lists of packed cell arrays (:func:`pack_cells`). Vectorised over all cells: one
    sort of the cells of ``b`` and a search of those of ``a`` (`kernels.overlap`), no loop
    over pairs."""
    na, nb = len(a), len(b)
    iou = np.zeros((na, nb))
    if na == 0 or nb == 0:
        return iou
    size_a = np.array([len(x) for x in a])
    size_b = np.array([len(x) for x in b])
    inter = shared_cells(a, b).astype(float)
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
    height: np.ndarray  # (K,) its heights (see OverlapTracker.update)
    group: int
    misses: int = 0
    hits: int = 1


class OverlapTracker:
    """Persistent ids for footprints on a fixed grid.

    min_iou: smallest footprint IoU for a detection to continue a track.
    height_tolerance: largest height difference (metres) between a track and its detection; with
    several heights each (a cluster's bottom and top), one of them within it is enough.
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
        """Live tracks by id: packed cells, height (the first), misses, hits."""
        return {
            t.id: {
                "cells": t.cells,
                "height": float(t.height[0]),
                "misses": t.misses,
                "hits": t.hits,
            }
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
        heights: (D,) or (D, K) float64 metres (K heights each: one within the tolerance of
        the track's matches). groups: (D,) int or None.
        """
        heights = np.asarray(heights, dtype=np.float64)
        heights = heights.reshape(len(heights), -1) if heights.ndim > 1 else heights[:, None]
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
        ok = iou >= self.min_iou
        if len(tracks):
            t_height = np.array([t.height for t in tracks]).reshape(len(tracks), -1)
            near = np.abs(heights[:, None, :] - t_height[None, :, :]) <= self.height_tolerance
            ok &= near.any(axis=2)
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
                t.cells, t.height, t.group = packed[r], heights[r].copy(), int(grp[r])
                t.misses, t.hits = 0, t.hits + 1
                matched[c] = True
        out = TrackUpdate(ids)
        for r in np.flatnonzero(ids < 0):  # new detections: a handful per scan
            t = _Track(self._next_id, packed[r], heights[r].copy(), int(grp[r]))
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
    rasterised on a ``cell_size`` grid, heights = bottom and top of the bounding box (either
    within the tolerance: an object first seen by its top over what hides the rest, then
    whole, keeps its id); ``group`` = the stable id of the surface under the cluster (-1 for
    none)."""

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
        ends = np.array([[c.bbox_min[2], c.bbox_max[2]] for c in clusters], np.float64)
        grp = (
            np.full(len(clusters), -1, np.int64)
            if surface_ids is None
            else np.asarray(surface_ids, np.int64).reshape(-1)
        )
        if len(grp) != len(clusters):
            raise InputError(f"{len(clusters)} clusters but {len(grp)} surface ids")
        return self._update_packed(packed, ends.reshape(len(clusters), 2), grp)
