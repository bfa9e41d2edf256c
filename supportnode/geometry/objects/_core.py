"""Supported objects: clusters of the points that lie on no support surface.

Two methods share one result type:
- ``knn``: Algorithm 2 of the report as published. Sample a fraction ``s`` of the candidates, link
  two samples when either is among the other's ``k`` nearest neighbours, take connected components;
  every candidate then takes the label of its nearest sample within ``label_radius``.
- ``voxel`` (default, the report's own suggestion): 26-connected components of the occupied voxels
  of a fine grid. No sampling, so no seed and no lost thin parts; linear in the number of points.

Both may then split *touching* objects (the report's main error: barrels side by side merged): a
cluster whose x, y footprint falls apart into large parts under a morphological opening of radius
``split_neck_width / 2`` is cut along the neck; one whose footprint has no neck but whose top is
two flat levels side by side, each standing on the surface (two boxes of different heights face
to face), is cut at the step. Clusters are never split vertically: a box standing on another
stays with it.

Each cluster is then attached to the surface directly under its lowest points, if any.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree

from supportnode.errors import InputError
from supportnode.geometry.linalg import sym3_eigen
from supportnode.geometry.memo import Memo
from supportnode.geometry.objects.convexity import cluster_convex
from supportnode.geometry.objects.neighbours import FORWARD_26
from supportnode.geometry.objects.support import supported_by
from supportnode.geometry.surfaces import Surface, SurfaceResult
from supportnode.params import ObjectParams

__all__ = [
    "Cluster",
    "Components",
    "ObjectResult",
    "Segmentation",
    "cluster_objects",
    "describe_objects",
    "detect_objects",
    "segment_objects",
    "split_objects",
]

# Points within this of a cluster's (robust) bottom are its "lowest points" for the support lookup.
_BOTTOM_BAND = 0.02
# A split part must hold at least this fraction of the cluster's footprint cells.
_SPLIT_MIN_FRACTION = 0.15
# A neck this much shallower than both parts it joins is cut (see _split_footprint).
_SPLIT_NECK_RATIO = 0.6
# Holes up to this area (m^2) are filled before the neck split (a side-scanned barrel is a
# ring); the room that a cluster of walls encloses is not a hole in one object's footprint.
_SPLIT_MAX_HOLE = 1.0
# Footprint raster cell = voxel_size / this (1 cm at the default 3 cm voxels).
_SPLIT_CELL_DIVISOR = 3.0
# Splitting at a step of the top height (see _split_step), metres and fractions: raster cell
# = voxel_size; neighbouring cells whose tops differ by at most _STEP_LINK are one plateau;
# two plateaus of >= _STEP_PART_FRACTION of the cells each, _STEP_COVER together, flat to
# _STEP_FLAT, _STEP_MIN apart, with _STEP_RIM_FREE of their rim beside free space, both reaching
# within _STEP_STAND of the cluster's bottom. Only clusters at most _STEP_MAX_EXTENT across
# (objects, not room structure) that fill _STEP_DENSE of their footprint raster are tried.
_STEP_LINK = 0.015
_STEP_PART_FRACTION = 0.3
_STEP_COVER = 0.7
_STEP_FLAT = 0.01
_STEP_MIN = 0.03
_STEP_RIM_FREE = 0.5
_STEP_STAND = 0.02
_STEP_MAX_EXTENT = 1.5
_STEP_DENSE = 0.9
# Splitting at concave creases (see _split_concave): voxels with at least _CONCAVE_MIN_POINTS
# points have a normal; a part must hold _CONCAVE_PART_FRACTION of the cluster's points, span
# _CONCAVE_PART_VOXELS voxels across in x and y, and reach within _STEP_STAND of the bottom.
_CONCAVE_MIN_POINTS = 3
_CONCAVE_PART_FRACTION = 0.1
_CONCAVE_PART_VOXELS = 2.0
# Only clusters at most this wide in x and y are tried (groups of objects, not room structure).
_CONCAVE_MAX_EXTENT = 1.0
# Recursion depth of splitting: up to 2**depth parts per cluster.
_SPLIT_DEPTH = 3
# A cluster stands on a surface when at least this fraction of its lowest points are over it.
_SUPPORT_MIN_FRACTION = 0.5
# Clusters of at least this many points drop the inner points of vertical lines before the
# hull (see _column_ends); below, the grouping costs more than Qhull saves.
_COLUMN_DEDUPE_MIN = 1000
# Footprints of up to this many vertices get their oriented boxes in one batch (see
# _oriented_rects), padded to the largest: at most 64 x 64 directions x vertices per cluster.
_RECT_BATCH_MAX = 64
# Odd 64-bit multipliers (golden ratio and a splitmix64 constant) hashing x, y bit patterns.
_HASH_X = np.uint64(0x9E3779B97F4A7C15)
_HASH_Y = np.uint64(0xBF58476D1CE4E5B9)
# Largest raster (surfaces + 1) x H x W of the one-pass support look-up (32 MB of int32).
_TABLE_MAX_CELLS = 8_000_000
# Voxel clustering uses a dense voxel -> id map up to this many grid cells per point (or this
# many cells in all): 2 M cells is a 6 x 5 x 2.5 m room at 3 cm, 10 MB of int32.
_DENSE_CELLS_PER_POINT = 64
_DENSE_MIN_CELLS = 4_000_000
# _edt_inner works on the occupied cells only of rasters of at least this many cells, at most
# _EDT_SPARSE_MAX_FILL of them occupied (a ring of walls: 2-4 %); scipy's on the rest.
_EDT_SPARSE_MIN_CELLS = 16_384
_EDT_SPARSE_MAX_FILL = 0.125
# _fill_holes first counts the holes (see _hole_count) on rasters of at least this many cells:
# a wall cluster's footprint (a thin ring, open at a door) usually has none.
_FILL_CHECK_MIN_CELLS = 65_536


@dataclass
class Cluster:
    """One supported object (or piece of structure). Lengths in metres, z up."""

    id: int  # 0 = largest by point count, then descending
    surface_id: int | None  # surface directly under the lowest points, None when on none
    point_count: int
    centroid: np.ndarray  # (3,) float64
    bbox_min: np.ndarray  # (3,) float64, axis-aligned box
    bbox_max: np.ndarray  # (3,) float64
    obb_center: np.ndarray  # (3,) float64, oriented box (yaw only)
    obb_size: np.ndarray  # (3,) float64: length >= width, height
    obb_yaw: float  # radians in (-pi/2, pi/2], direction of the length axis
    height: float  # top above the surface height (above its own bottom when surface_id is None)
    footprint: np.ndarray  # (K, 2) float64 convex hull in x, y, counter-clockwise
    volume: float  # convex-hull volume, m^3 (0 for degenerate sets)
    supported_by: int = -1  # id of the cluster it stands on, -1 when on its surface (or none)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (no numpy types)."""
        return {
            "id": int(self.id),
            "surface_id": None if self.surface_id is None else int(self.surface_id),
            "point_count": int(self.point_count),
            "centroid": [float(v) for v in self.centroid],
            "bbox_min": [float(v) for v in self.bbox_min],
            "bbox_max": [float(v) for v in self.bbox_max],
            "obb_center": [float(v) for v in self.obb_center],
            "obb_size": [float(v) for v in self.obb_size],
            "obb_yaw": float(self.obb_yaw),
            "height": float(self.height),
            "footprint": np.round(self.footprint, 4).tolist(),
            "volume": float(self.volume),
            "supported_by": int(self.supported_by),
        }


@dataclass
class ObjectResult:
    """Clusters sorted largest first (ids 0, 1, ... in that order) and a label per input point."""

    clusters: list[Cluster]
    labels: np.ndarray  # (N,) int32: cluster id of each input point, -1 for none
    stats: dict = field(default_factory=dict)


@dataclass
class Segmentation:
    """Objects segmented but not yet described: what free space needs, before the hulls.

    labels: (N,) int32 cluster id of each input point, -1 for none; ids are the final ones
    (largest first), so :func:`describe_objects` only adds the clusters' geometry.
    surface_ids: (C,) int64 surface under each cluster, -1 for none. bbox_min, bbox_max:
    (C, 3) float64 axis-aligned boxes of the clusters' points, metres.
    """

    labels: np.ndarray
    surface_ids: np.ndarray
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    stats: dict = field(default_factory=dict)
    # For describe_objects: the clustered points grouped by cluster (old order) and the run
    # [start, end) of each cluster in the new order.
    _grouped: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    _runs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64), repr=False)
    _heights: dict = field(default_factory=dict, repr=False)


def detect_objects(
    points: np.ndarray,
    surfaces: SurfaceResult,
    params: ObjectParams | None = None,
    memo: Memo | None = None,
) -> ObjectResult:
    """Cluster the points that lie on no surface into objects.

    points: (N, 3) float, metres, z up. surfaces: the result of surface detection on the same
    points (``surfaces.labels`` is (N,), -1 for the candidates clustered here).
    Returns clusters sorted by point count (ties broken by position, so the result does not depend
    on point order) and (N,) int32 labels, -1 for surface points, noise and unlabelled points.
    memo: per-cluster results (splits, hulls) of the previous call, reused for clusters with
    the very same points (the node's map changes in a few places per scan); the same result.
    Raises InputError on a wrong shape, non-finite values or a label array of the wrong length.
    The same as :func:`describe_objects` of :func:`segment_objects`.
    """
    return describe_objects(segment_objects(points, surfaces, params, memo), memo)


@dataclass
class Components:
    """Connected components of the points on no surface, before touching objects are split:
    what free space needs (a pile of objects occupies its surface however it is split), and
    what :func:`split_objects` continues from.

    segmentation: the components as a Segmentation (labels (N,), largest first, their
    supporting surfaces and boxes). The other fields are for split_objects.
    """

    segmentation: Segmentation
    _points: np.ndarray = field(repr=False)  # (M, 3) float64 candidate points
    _candidates: np.ndarray = field(repr=False)  # (M,) int64 their rows in the input
    _labels: np.ndarray = field(repr=False)  # (M,) int64 component of each candidate, -1: none
    _supports: np.ndarray = field(repr=False)  # (C,) int64 surface of each component by label
    _lookups: list = field(repr=False)
    _n_points: int = 0
    _stats: dict = field(default_factory=dict, repr=False)


def segment_objects(
    points: np.ndarray,
    surfaces: SurfaceResult,
    params: ObjectParams | None = None,
    memo: Memo | None = None,
) -> Segmentation:
    """The first half of :func:`detect_objects` (same arguments and errors): clusters, their
    order, labels and supporting surfaces, without the hulls and boxes that describe them.
    The same as :func:`split_objects` of :func:`cluster_objects`."""
    params = params or ObjectParams()
    return split_objects(cluster_objects(points, surfaces, params), params, memo)


def cluster_objects(
    points: np.ndarray,
    surfaces: SurfaceResult,
    params: ObjectParams | None = None,
    sensor_origin: np.ndarray | None = None,
) -> Components:
    """Connected components of the points on no surface (arguments and errors as for
    :func:`detect_objects`), each with the surface it stands on: touching objects not split
    yet. Free space is computed from these (see `supportnode.geometry.freespace`).
    sensor_origin: (3,) sensor position in the points' frame when known (the convex method
    turns its normals toward it and widens the table band with range)."""
    params = params or ObjectParams()
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {pts.shape}")
    surf_labels = np.asarray(surfaces.labels)
    if surf_labels.shape != (len(pts),):
        raise InputError(f"surface labels have shape {surf_labels.shape}, expected ({len(pts)},)")
    if not np.isfinite(pts).all():
        raise InputError("points contain NaN or infinite values")

    t0 = time.perf_counter()
    cand = np.flatnonzero(surf_labels == -1)
    cp = np.take(pts, cand, axis=0)  # np.take: 5x faster than pts[cand] for (N, 3) rows
    stats: dict = {"method": params.method, "candidates": len(cand)}
    lookups = _lookups(surfaces.surfaces)
    if params.method == "knn":
        lab = _cluster_knn(cp, params, stats)
    elif params.method == "voxel":
        support = _support_below(cp, surfaces.surfaces, params.support_tolerance, lookups)
        lab = _cluster_voxel(cp, params.voxel_size, stats, support)
    elif params.method == "convex":
        support = _support_below(cp, surfaces.surfaces, params.support_tolerance, lookups)
        lab = cluster_convex(cp, surfaces.surfaces, support, params, sensor_origin, stats)
    else:
        raise InputError(
            f"unknown object method {params.method!r}; expected 'knn', 'voxel' or 'convex'"
        )
    lab = _drop_small(lab, params.min_points)
    stats["components"] = int(lab.max() + 1) if len(lab) else 0
    seg = _order(cp, lab, lookups[1], params)
    # Each component's surface by its label, for split_objects: a component that is not
    # split keeps its points, so its surface (a function of them) is this one.
    n = stats["components"]
    of_label = np.full(n, -1, dtype=np.int64)
    ok = lab >= 0
    of_label[lab[ok]] = seg.labels[ok]
    sids = seg.surface_ids[of_label] if n else np.zeros(0, np.int64)
    seg.labels = _full_labels(len(pts), cand, seg.labels)
    stats["time_cluster_s"] = time.perf_counter() - t0
    seg.stats = {"components": n}
    return Components(seg, cp, cand, lab, sids, lookups, len(pts), stats)


def split_objects(
    components: Components, params: ObjectParams | None = None, memo: Memo | None = None
) -> Segmentation:
    """The objects of :func:`cluster_objects`' components: touching objects split (when
    ``params.split_touching``), ordered largest first, with their supporting surfaces (the
    second half of :func:`segment_objects`). memo: as for :func:`detect_objects`."""
    params = params or ObjectParams()
    cp, lab = components._points, components._labels
    stats = dict(components._stats)
    t1 = time.perf_counter()
    stats["merged_splits"] = 0  # clusters cut into parts at a thin footprint neck
    stats["split_parts"] = 0
    stats["step_splits"] = 0  # of which cut at a step of the top height
    stats["concave_splits"] = 0  # of which cut along concave creases
    known = components._supports
    split = lab
    if params.split_touching and len(lab):
        split = _split_touching(cp, lab, params, stats, memo)
    t2 = time.perf_counter()
    if stats["merged_splits"] == 0:
        # Nothing split (the usual case): the clusters are the components, in their order.
        seg = dataclasses.replace(components.segmentation, stats=stats)
    else:
        n = len(known)
        # A label keeps its points unless its cluster was split (part 0 keeps the label):
        # only those, and the new parts, need their surface found again.
        before = np.bincount(lab[lab >= 0], minlength=n)
        after = np.bincount(split[split >= 0], minlength=n)
        known = np.concatenate([known, np.full(len(after) - n, -2, np.int64)])
        known[:n][after[:n] != before] = -2
        seg = _order(cp, split, components._lookups[1], params, known)
        seg.labels = _full_labels(components._n_points, components._candidates, seg.labels)
        seg.stats = stats
    stats["clusters"] = len(seg.surface_ids)
    stats["labelled_points"] = int((seg.labels >= 0).sum())
    stats["time_split_s"] = t2 - t1
    stats["time_order_s"] = time.perf_counter() - t2
    return seg


def _full_labels(n: int, cand: np.ndarray, lab: np.ndarray) -> np.ndarray:
    """(n,) int32 labels of all points from those (M,) of the candidates at rows cand."""
    labels = np.full(n, -1, dtype=np.int32)
    labels[cand] = lab
    return labels


def describe_objects(seg: Segmentation, memo: Memo | None = None) -> ObjectResult:
    """The second half of :func:`detect_objects`: the clusters of ``seg`` described (hulls,
    oriented boxes, heights). memo: as for detect_objects."""
    t = time.perf_counter()
    clusters = _describe(seg, memo)
    _stack(clusters, seg._heights)
    stats = dict(seg.stats)
    stats["time_describe_s"] = time.perf_counter() - t + stats.pop("time_order_s", 0.0)
    return ObjectResult(clusters=clusters, labels=seg.labels, stats=stats)


def _stack(clusters: list[Cluster], heights: dict) -> None:
    """Set each cluster's supported_by (see objects.support); a cluster standing on another
    with no surface of its own takes the surface under its stack."""
    if len(clusters) < 2:
        return
    lo = np.array([c.bbox_min for c in clusters])
    hi = np.array([c.bbox_max for c in clusters])
    base = np.array(
        [np.nan if c.surface_id is None else heights.get(c.surface_id, np.nan) for c in clusters]
    )
    if np.isnan(base).all() and not heights:
        return
    by = supported_by(lo, hi, base)
    for c, b in zip(clusters, by.tolist(), strict=True):
        c.supported_by = int(b)
    for c in clusters:
        seen, k = set(), c
        while c.surface_id is None and k.supported_by >= 0 and k.id not in seen:
            seen.add(k.id)
            k = clusters[k.supported_by]
        if c.surface_id is None and k.surface_id is not None:
            c.surface_id = k.surface_id


# ------------------------------------------------------------------------------------ clustering


def _cluster_knn(cp: np.ndarray, params: ObjectParams, stats: dict) -> np.ndarray:
    """The report's Algorithm 2 on candidates cp (M, 3); returns (M,) int64 labels, -1 = none."""
    m = len(cp)
    n_s = min(m, max(1, round(params.sample_fraction * m))) if m else 0
    stats["sampled"] = n_s
    if n_s == 0:
        return np.full(m, -1, dtype=np.int64)
    rng = np.random.default_rng(params.seed)
    # Sorted indices: the sample does not depend on which sample index came out first.
    sample_idx = np.sort(rng.choice(m, size=n_s, replace=False)) if n_s < m else np.arange(m)
    sample = cp[sample_idx]
    tree = cKDTree(sample)
    k = min(params.k, n_s - 1)
    if k >= 1:
        _, nbr = tree.query(sample, k=k + 1, workers=-1)
        rows = np.repeat(np.arange(n_s), k)
        cols = nbr[:, 1:].ravel()  # column 0 is the point itself
        graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(n_s, n_s))
        # directed=False symmetrises: linked when either is among the other's k neighbours.
        _, comp = connected_components(graph.tocsr(), directed=False)
    else:
        comp = np.zeros(n_s, dtype=np.int64)
    if n_s == m:
        return comp.astype(np.int64)
    dist, near = tree.query(cp, k=1, distance_upper_bound=params.label_radius, workers=-1)
    lab = np.full(m, -1, dtype=np.int64)
    ok = np.isfinite(dist)
    lab[ok] = comp[near[ok]]
    return lab


def _support_below(
    cp: np.ndarray,
    surfaces: list[Surface],
    tol: float,
    lookups: tuple[list[_SupportLookup], list[_SupportLookup]] | None = None,
) -> np.ndarray:
    """(M,) int64: the highest surface under each point of cp (M, 3), -1 when none.

    A point is over a surface when its x, y falls on the surface's (filled) footprint and it is
    no more than ``tol`` below the surface's height. lookups: the surfaces' lookups undilated
    and dilated (see _lookups), built here when None.
    """
    plain, dilated = lookups if lookups is not None else _lookups(surfaces)
    by_id = {s.id: k for k, s in enumerate(surfaces)}
    sup = np.full(len(cp), -1, dtype=np.int64)
    ordered = sorted(surfaces, key=lambda s: s.height)
    # The ground (lowest surface with nothing below it) is dilated: a wall standing on its
    # ragged edge would otherwise alternate between "over the floor" and "over nothing" and
    # fall into strips.
    ground = (
        ordered[0] if ordered and len(cp) and cp[:, 2].min() >= ordered[0].height - tol else None
    )
    # Undilated: a chair back rising just beside a table must not be cut at table height.
    lks = [(dilated if s is ground else plain)[by_id[s.id]] for s in ordered]
    table = _SupportTable.build(lks, tol)
    if table is not None:
        return table.lookup(cp)
    cells = _CellIndex(cp[:, :2])  # floor(xy / cell) once per cell size, not once per surface
    z = cp[:, 2]
    for lk in lks:  # higher surfaces overwrite lower ones
        idx = np.flatnonzero(z >= lk.height - tol)
        sup[idx[lk.over_cells(cells.of(lk.cell), idx)]] = lk.id
    return sup


@dataclass
class _SupportTable:
    """All surfaces' footprints on one raster, for :func:`_support_below` in one pass.

    ``best[k, i, j]``: id of the highest of the first k surfaces (by height) whose footprint
    covers cell (i, j), -1 for none. A point at height z is over exactly the surfaces whose
    ``height - tol`` is at most z, a prefix of k of them, so its support is one look-up; the
    same answer as overwriting the support surface by surface in height order.
    """

    cell: np.ndarray  # (2,) m, shared by all surfaces
    origin: np.ndarray  # (2,) int64 cell index of best[:, 0, 0]
    best: np.ndarray  # (S + 1, H, W) int32
    threshold: np.ndarray  # (S,) ascending height - tol, m

    @classmethod
    def build(cls, lookups: list[_SupportLookup], tol: float) -> _SupportTable | None:
        """From lookups sorted by height; None when their grids differ or the raster would
        exceed _TABLE_MAX_CELLS (then surfaces are tested one by one)."""
        if not lookups or len({(float(lk.cell[0]), float(lk.cell[1])) for lk in lookups}) != 1:
            return None
        used = [lk for lk in lookups if lk.mask.any()]  # an empty footprint covers no cell
        if not used:
            return None
        lo = np.min([lk.origin for lk in used], axis=0)
        hi = np.max([lk.origin + lk.mask.shape for lk in used], axis=0)
        h, w = (int(v) for v in hi - lo)
        if (len(lookups) + 1) * h * w > _TABLE_MAX_CELLS:
            return None
        best = np.full((len(lookups) + 1, h, w), -1, dtype=np.int32)
        for k, lk in enumerate(lookups):  # one raster per surface
            best[k + 1] = best[k]
            if lk.mask.any():
                i0, j0 = (int(v) for v in lk.origin - lo)
                region = best[k + 1, i0 : i0 + lk.mask.shape[0], j0 : j0 + lk.mask.shape[1]]
                region[lk.mask] = lk.id
        threshold = np.array([lk.height - tol for lk in lookups])
        return cls(lookups[0].cell, lo, best, threshold)

    def lookup(self, cp: np.ndarray) -> np.ndarray:
        """(M,) int64 support surface id of each point of cp (M, 3), -1 for none."""
        k = np.searchsorted(self.threshold, cp[:, 2], side="right")  # surfaces at or below
        i = np.floor(cp[:, 0] / self.cell[0]).astype(np.int64) - self.origin[0]
        j = np.floor(cp[:, 1] / self.cell[1]).astype(np.int64) - self.origin[1]
        _, h, w = self.best.shape
        outside = (i.astype(np.uint64) >= h) | (j.astype(np.uint64) >= w)
        # One flat gather for all points (those outside read cell 0, then get -1): 3x faster
        # than gathering k, i, j at the inside points and indexing the 3-D table with them.
        flat = (k * h + i) * w + j
        flat[outside] = 0
        sup = np.take(self.best.reshape(-1), flat).astype(np.int64)
        sup[outside] = -1
        return sup


def _lookups(surfaces: list[Surface]) -> tuple[list[_SupportLookup], list[_SupportLookup]]:
    """Lookups of the surfaces, undilated and dilated by one cell (filled once for both)."""
    plain = [_SupportLookup(s, dilate=False) for s in surfaces]
    return plain, [lk.dilated() for lk in plain]


def _cluster_voxel(
    cp: np.ndarray, voxel_size: float, stats: dict, support: np.ndarray | None = None
) -> np.ndarray:
    """26-connected occupied voxels; cp (M, 3) metres -> (M,) int64 component per point.

    support: optional (M,) surface under each point; voxels over different surfaces are not
    linked, so objects on a shelf board do not join the shelf's frame (over the floor) or the
    objects on the board below through it.
    """
    m = len(cp)
    stats["sampled"] = m
    if m == 0:
        stats["voxels"] = 0
        return np.zeros(0, dtype=np.int64)
    # +1: a one-voxel empty border, so a neighbour offset can never wrap into the next row.
    # Column by column (see _col); truncation is floor here, the offsets being >= 0.
    ijk = [((c - c.min()) / voxel_size).astype(np.int64) + 1 for c in cp.T]
    dims = np.array([c.max() + 2 for c in ijk], dtype=np.int64)
    strides = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
    keys = ijk[0] * strides[0] + ijk[1] * strides[1] + ijk[2]
    cells = int(dims.prod())
    rows, cols = [], []
    if cells <= max(_DENSE_MIN_CELLS, _DENSE_CELLS_PER_POINT * m):
        # A dense voxel -> id map: no sort, and each neighbour test is one gather. Same sorted
        # voxel numbering and the same edges as np.unique + searchsorted below, 2-3x faster.
        occupied = np.zeros(cells, dtype=bool)
        occupied[keys] = True
        vkeys = np.flatnonzero(occupied)
        nv = len(vkeys)
        # Ids only at occupied cells (the rest is never read): no fill of the whole grid, and
        # the neighbour tests read the 4x smaller occupancy.
        vid = np.empty(cells, dtype=np.int32 if nv < 2**31 else np.int64)
        vid[vkeys] = np.arange(nv)
        inv = vid[keys].astype(np.int64)
        for off in FORWARD_26 @ strides:  # 13 vectorised look-ups, not a loop over voxels
            nbk = vkeys + off  # never out of range: the empty border absorbs every offset
            hit = np.flatnonzero(occupied[nbk])
            rows.append(hit)
            cols.append(vid[nbk[hit]])
    else:
        vkeys, inv = np.unique(keys, return_inverse=True)
        nv = len(vkeys)
        for off in FORWARD_26 @ strides:
            pos = np.searchsorted(vkeys, vkeys + off)
            pos = np.minimum(pos, nv - 1)
            hit = np.flatnonzero(vkeys[pos] == vkeys + off)
            rows.append(hit)
            cols.append(pos[hit])
    stats["voxels"] = int(nv)
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    if support is not None:
        # The highest support among a voxel's points: independent of point order.
        vsup = np.full(nv, -1, dtype=np.int64)
        np.maximum.at(vsup, inv.ravel(), support)
        same = vsup[r] == vsup[c]
        stats["support_cuts"] = int((~same).sum())
        r, c = r[same], c[same]
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(nv, nv))
    _, comp = connected_components(graph.tocsr(), directed=False)
    return comp[inv.ravel()].astype(np.int64)


def _drop_small(lab: np.ndarray, min_points: int) -> np.ndarray:
    """Relabel to 0..K-1 keeping components with >= min_points points; others become -1."""
    out = np.full(len(lab), -1, dtype=np.int64)
    ok = lab >= 0
    if not ok.any():
        return out
    # Counting instead of np.unique: no sort, and kept labels stay in ascending order.
    counts = np.bincount(lab[ok])
    keep = counts >= min_points
    new_id = np.full(len(counts), -1, dtype=np.int64)
    new_id[keep] = np.arange(int(keep.sum()))
    out[ok] = new_id[lab[ok]]
    return out


# ------------------------------------------------------------------------------ touching objects


def _split_touching(
    cp: np.ndarray, lab: np.ndarray, params: ObjectParams, stats: dict, memo: Memo | None = None
) -> np.ndarray:
    """Cut clusters whose x, y footprint has large parts joined by a neck (see _split_footprint),
    or else whose top steps between two flat levels side by side (see _split_step). memo: the
    cuts of clusters seen with the same points in the previous detection."""
    cell = params.voxel_size / _SPLIT_CELL_DIVISOR
    radius = params.split_neck_width / 2.0
    n = int(lab.max()) + 1
    out = lab.copy()
    if n == 0:
        return out
    order = _group_by_label(lab)
    bounds = np.searchsorted(lab[order], np.arange(-1, n + 1))
    # Footprint extents of all clusters at once, to skip the clusters too narrow to split
    # without gathering their points (most clusters: wall strips, small objects).
    # Contiguous (np.take on a strided view copies it first), column by column: copying the
    # (M, 2) view in one go runs numpy's inner loop over 2 elements, 6x slower.
    all_xy = np.empty((len(cp), 2))
    all_xy[:, 0] = cp[:, 0]
    all_xy[:, 1] = cp[:, 1]
    xy = np.take(all_xy, order[bounds[1] :], axis=0)
    starts = np.minimum(bounds[1:-1] - bounds[1], len(xy) - 1)
    nonempty = bounds[2:] > bounds[1:-1]
    lo = np.minimum.reduceat(xy, starts, axis=0)
    hi = np.maximum.reduceat(xy, starts, axis=0)
    shape = np.floor((hi - lo) / cell).astype(np.int64) + 3  # as _split_footprint rasterises
    next_id = n
    for c in np.flatnonzero(nonempty & _may_split(shape, cell, radius)):  # wide clusters only
        idx = order[bounds[c + 1] : bounds[c + 2]]
        extent = float((hi[c] - lo[c]).max())
        if memo is None:
            parts, n_parts, how = _split_one(cp, idx, all_xy, extent, params, cell, radius)
        else:  # a pure function of the cluster's points (its extent is theirs)
            parts, n_parts, how = memo.get(
                "split",
                np.take(cp, idx, axis=0),
                lambda idx=idx, extent=extent: _split_one(
                    cp, idx, all_xy, extent, params, cell, radius
                ),
            )
        if how is not None:
            stats[how] += 1
        if n_parts < 2:
            continue
        stats["merged_splits"] += 1
        stats["split_parts"] += n_parts
        # Part 0 keeps the cluster's id; the others take fresh ids (ids are re-sorted later).
        rest = parts > 0
        out[idx[rest]] = next_id + parts[rest] - 1
        next_id += n_parts - 1
    return out


def _split_one(
    cp: np.ndarray,
    idx: np.ndarray,
    all_xy: np.ndarray,
    extent: float,
    params: ObjectParams,
    cell: float,
    radius: float,
) -> tuple[np.ndarray, int, str | None]:
    """Parts (P,) of the cluster of points cp[idx] (x, y footprint extent in metres), their
    number, and the stats key of the rule that cut it ("step_splits", "concave_splits"; None
    for a neck or no cut)."""
    xy_c = np.take(all_xy, idx, axis=0)
    parts = _split_recursive(xy_c, cell, radius, params.min_points, _SPLIT_DEPTH)
    n_parts = int(parts.max()) + 1
    if n_parts >= 2 or extent > _STEP_MAX_EXTENT:
        return parts, n_parts, None
    p_c = np.take(cp, idx, axis=0)
    step, dense = _split_step(p_c, params.voxel_size, params.min_points)
    if step is not None:
        return step, 2, "step_splits"
    if dense and params.split_concave and extent <= _CONCAVE_MAX_EXTENT:
        # Not tried on sparse footprints (far scans) or wide structure.
        conc = _split_concave(p_c, params.voxel_size, params.concave_tolerance, params.min_points)
        if conc is not None:
            return conc, int(conc.max()) + 1, "concave_splits"
    return parts, n_parts, None


def _may_split(shape: np.ndarray, cell: float, radius: float) -> np.ndarray:
    """(...,) bool: whether a footprint raster of shape (..., 2) cells can hold a split part.

    The raster has an empty border, so no cell is deeper (further from the footprint's edge)
    than half the narrower side, floor((min(shape) - 1) / 2) - 0.5 cells; a part needs a cell
    of depth 1.5 * radius (see _split_footprint). False is exact: such a raster never splits.
    """
    narrow = shape.min(axis=-1)
    deepest = np.floor((narrow - 1) / 2) - 0.5
    return (narrow >= 5) & (deepest * cell >= 1.5 * radius)


def _split_step(p: np.ndarray, cell: float, min_points: int) -> tuple[np.ndarray | None, bool]:
    """(P,) part 0 or 1 per point of p (P, 3) when its top is two flat levels, else None; and
    whether the cluster's footprint is dense enough to be tried (see below).

    Boxes of different heights standing face to face have one rectangular footprint, no neck;
    only the top height steps. On a raster of cell (the voxel size), cells whose top heights
    differ by at most _STEP_LINK join into plateaus (8-connected). The cluster splits when
    exactly two plateaus each cover _STEP_PART_FRACTION of the occupied cells and together
    _STEP_COVER, are flat (top s.d. <= _STEP_FLAT), differ by >= _STEP_MIN, each border free
    space along _STEP_RIM_FREE of their rim, and both reach down to the cluster's bottom
    (within _STEP_STAND): a toy car's cabin or a stacked box sits on the part below, a box
    beside another stands on the table. Sparsely sampled clusters (occupied cells under
    _STEP_DENSE of the footprint) are not tried. Each part must hold min_points points.
    Known false cut: one object whose side profile is an L (a step stool) looks the same.
    """
    lo = _col(np.minimum, p[:, :2])
    ij = ((p[:, :2] - lo) / cell).astype(np.int64)  # truncation = floor (>= 0)
    h, w = (int(v) + 1 for v in _col(np.maximum, ij))
    key = ij[:, 0] * w + ij[:, 1]
    top = np.full(h * w, -np.inf)
    np.maximum.at(top, key, p[:, 2])  # top height of every cell, -inf when empty
    cells = np.flatnonzero(np.isfinite(top))
    if len(cells) < 2:
        return None, False
    grid = top.reshape(h, w)
    # Sparse sampling (a distant scan) leaves empty cells inside the footprint, where neither
    # the levels nor the free space around them can be judged: such clusters are not tried.
    occupied = np.zeros((h + 2, w + 2), dtype=bool)  # np.pad(..., 1), without its overhead
    occupied[1:-1, 1:-1] = np.isfinite(grid)
    solid = _fill_holes(_close3(occupied))
    if len(cells) < _STEP_DENSE * solid.sum():
        return None, False
    vid = np.full((h, w), -1, dtype=np.int64)
    vid.flat[cells] = np.arange(len(cells))
    rows, cols = [], []
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):  # the four forward 8-neighbours
        a = (slice(0, h - di), slice(max(0, -dj), w - max(0, dj)))
        b = (slice(di, h), slice(max(0, dj), w - max(0, -dj)))
        with np.errstate(invalid="ignore"):  # -inf - -inf between empty cells
            link = np.abs(grid[a] - grid[b]) <= _STEP_LINK
        rows.append(vid[a][link])
        cols.append(vid[b][link])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(len(cells),) * 2)
    _, plateau = connected_components(graph.tocsr(), directed=False)
    size = np.bincount(plateau)
    big = np.flatnonzero(size >= _STEP_PART_FRACTION * len(cells))
    if len(big) != 2 or size[big].sum() < _STEP_COVER * len(cells):
        return None, True
    tops = [top[cells[plateau == k]] for k in big]
    if abs(float(np.median(tops[0]) - np.median(tops[1]))) < _STEP_MIN:
        return None, True
    if max(float(t.std()) for t in tops) > _STEP_FLAT:
        return None, True
    # Each level must stand beside the other, not on it: most of its rim borders free space
    # (a box beside a box: three of four sides; a stacked box: none).
    # Within two cells: a box's edge cells hold its sides' points, lower than its top.
    near_free = ndimage.binary_dilation(~solid, structure=np.ones((5, 5), dtype=bool))[1:-1, 1:-1]
    for k in big:  # two plateaus
        mine = np.zeros(h * w, dtype=bool)
        mine[cells[plateau == k]] = True
        mine = mine.reshape(h, w)
        rim = mine & ~ndimage.binary_erosion(mine, np.ones((3, 3), dtype=bool), border_value=0)
        if (rim & near_free).sum() < _STEP_RIM_FREE * rim.sum():
            return None, True
    # Points go by a raster three times finer, whose cells take the plateau their top height
    # matches (the coarse cells at the step hold both levels), else the nearest such cell.
    level = np.array([np.median(t) for t in tops])
    fine = ((p[:, :2] - lo) / (cell / 3.0)).astype(np.int64)
    fh, fw = (int(v) + 1 for v in _col(np.maximum, fine))
    fkey = fine[:, 0] * fw + fine[:, 1]
    ftop = np.full(fh * fw, -np.inf)
    np.maximum.at(ftop, fkey, p[:, 2])
    gap = np.abs(ftop[:, None] - level[None, :])  # (cells, 2) m; inf for empty cells
    mark = np.where(gap.min(axis=1) <= _STEP_LINK, np.argmin(gap, axis=1) + 1, 0)
    mark = mark.reshape(fh, fw)
    if not mark.any():
        return None, True
    _, (ni, nj) = ndimage.distance_transform_edt(mark == 0, return_indices=True)
    part = mark[ni, nj].ravel()[fkey] - 1
    counts = np.bincount(part, minlength=2)
    if counts.min() < min_points:
        return None, True
    bottom = np.percentile(p[:, 2], 1.0)
    for n in range(2):
        if np.percentile(p[part == n, 2], 2.0) - bottom > _STEP_STAND:
            return None, True  # one level stands on the other, not on the surface
    return (part if counts[0] >= counts[1] else 1 - part), True  # part 0 the larger


def _split_concave(p: np.ndarray, voxel: float, tol: float, min_points: int) -> np.ndarray | None:
    """(P,) part index per point of p (P, 3) when it falls apart at concave creases, else None.

    Touching convex objects (barrels in a triangle, whose footprint has no neck once its small
    inner gap is filled) meet along a concave crease, as in LCCP (Stein et al. 2014). Each
    voxel of edge ``voxel`` with _CONCAVE_MIN_POINTS points has a normal (smallest eigenvector
    of its points' scatter), oriented away from the cluster's centroid (outward for a convex
    part that contains it). A link between 26-neighbours i, j is concave when
    ``(n_i - n_j) . (c_i - c_j) < -tol * |c_i - c_j|`` (c: voxel centroids; >= 0 on a convex
    surface). The voxels of concave links are removed; the remaining connected components are
    parts when they hold _CONCAVE_PART_FRACTION of the points (and min_points), span
    _CONCAVE_PART_VOXELS voxels in x and y, and stand within _STEP_STAND of the cluster's
    bottom: side by side on the surface, as for _split_step, so a lamp's shade, a toy car's
    cabin, a stacked box or a chair's back stays with what it stands on. Every point then
    goes to the part with the nearest point in x, y (columns are never cut). Parts by size.
    """
    if len(p) < 2 * max(min_points, 1):
        return None
    q = p - _col(np.add, p) / len(p)  # centred: moments without cancellation; centroid 0
    ijk = [np.floor((c - c.min()) / voxel).astype(np.int64) + 1 for c in q.T]
    dims = np.array([c.max() + 2 for c in ijk], dtype=np.int64)
    strides = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
    keys = ijk[0] * strides[0] + ijk[1] * strides[1] + ijk[2]
    vkeys, inv = np.unique(keys, return_inverse=True)
    inv = inv.ravel()
    nv = len(vkeys)
    if nv < 3:
        return None
    cnt = np.bincount(inv, minlength=nv).astype(np.float64)
    cen = np.stack([np.bincount(inv, q[:, a], nv) for a in range(3)], axis=1) / cnt[:, None]
    cov = np.empty((nv, 3, 3))
    for a in range(3):  # six second moments, not a loop over voxels
        for b in range(a, 3):
            m = np.bincount(inv, q[:, a] * q[:, b], nv) / cnt - cen[:, a] * cen[:, b]
            cov[:, a, b] = cov[:, b, a] = m
    _, normal = sym3_eigen(cov)
    flip = (normal * cen).sum(axis=1) < 0  # outward: away from the centroid (the origin)
    normal[flip] *= -1.0
    good = cnt >= _CONCAVE_MIN_POINTS
    rows, cols = [], []
    for off in FORWARD_26 @ strides:  # 13 vectorised look-ups, not a loop over voxels
        pos = np.minimum(np.searchsorted(vkeys, vkeys + off), nv - 1)
        hit = np.flatnonzero(vkeys[pos] == vkeys + off)
        rows.append(hit)
        cols.append(pos[hit])
    r, c = np.concatenate(rows), np.concatenate(cols)
    dc = cen[r] - cen[c]
    conv = ((normal[r] - normal[c]) * dc).sum(axis=1)
    concave = good[r] & good[c] & (conv < -tol * np.sqrt((dc * dc).sum(axis=1)))
    if not concave.any():
        return None
    crease = np.zeros(nv, dtype=bool)
    crease[r[concave]] = True
    crease[c[concave]] = True
    keep = ~crease[r] & ~crease[c]
    graph = coo_matrix((np.ones(int(keep.sum()), dtype=np.int8), (r[keep], c[keep])), (nv, nv))
    _, comp = connected_components(graph.tocsr(), directed=False)
    comp[crease] = -1
    pcomp = comp[inv]
    ok = pcomp >= 0
    n_comp = int(comp.max()) + 1
    size = np.bincount(pcomp[ok], minlength=n_comp)
    cand = np.flatnonzero(size >= max(min_points, _CONCAVE_PART_FRACTION * len(p)))
    if len(cand) < 2:
        return None
    bottom = np.percentile(q[:, 2], 1.0)
    parts = []
    for k in cand:  # a few large components
        sel = np.flatnonzero(pcomp == k)
        ext = _col(np.maximum, q[sel, :2]) - _col(np.minimum, q[sel, :2])
        if ext.min() < _CONCAVE_PART_VOXELS * voxel:
            continue
        if np.percentile(q[sel, 2], 2.0) - bottom > _STEP_STAND:
            continue  # stands on another part, not on the surface
        parts.append(sel)
    if len(parts) < 2:
        return None
    seed = np.concatenate(parts)
    seed_part = np.repeat(np.arange(len(parts)), [len(s) for s in parts])
    _, near = cKDTree(q[seed, :2]).query(q[:, :2], k=1)
    part = seed_part[near]
    counts = np.bincount(part, minlength=len(parts))
    if counts.min() < min_points:
        return None
    rank = np.empty(len(counts), dtype=np.int64)
    rank[np.argsort(-counts, kind="stable")] = np.arange(len(counts))
    return rank[part]


def _split_recursive(
    xy: np.ndarray, cell: float, radius: float, min_points: int, depth: int
) -> np.ndarray:
    """(P,) part index per point of xy (P, 2): a row of three barrels splits twice."""
    parts = _split_footprint(xy, cell, radius, min_points) if depth > 0 else None
    if parts is None:
        return np.zeros(len(xy), dtype=np.int64)
    out = np.empty(len(xy), dtype=np.int64)
    n = 0
    for k in range(int(parts.max()) + 1):  # two or three parts
        sel = np.flatnonzero(parts == k)
        sub = _split_recursive(np.take(xy, sel, axis=0), cell, radius, min_points, depth - 1)
        out[sel] = sub + n
        n += int(sub.max()) + 1
    return out


def _big_parts(occ: np.ndarray, n_cells: int, comp: np.ndarray, deep: np.ndarray) -> np.ndarray:
    """(n,) bool: the deep parts (deep (n,), parts labelled 1..n in comp (H, W)) whose area, the
    cells of the footprint occ (H, W) (n_cells of them) nearest to the part, is at least
    _SPLIT_MIN_FRACTION of the footprint.

    A cell equidistant from two parts goes to either, as scipy's feature transform picks. On a
    big, sparse raster (a ring of walls: a 500 x 400 raster, 1-5k footprint cells) the
    transform of the whole raster costs 8-12 ms. There, each footprint cell's squared distance
    to every deep part comes from a k-d tree of the part's cells (exact on integer cells), and
    the areas counting tied cells for no part and for every part bound the true ones; when
    both bounds agree on every part, that is the answer, else the transform decides.
    """
    n = len(deep)
    if occ.size >= _EDT_SPARSE_MIN_CELLS and n_cells <= _EDT_SPARSE_MAX_FILL * occ.size:
        ci, cj = np.divmod(np.flatnonzero(occ), occ.shape[1])
        lab = comp[ci, cj]  # 0 outside the level's set
        parts = np.flatnonzero(deep) + 1
        is_part = deep[np.maximum(lab - 1, 0)] & (lab > 0)
        # A part's own cells are at distance 0 from it only: they count for it alone.
        own = np.bincount(lab[is_part], minlength=n + 1)[parts]
        qi, qj = ci[~is_part], cj[~is_part]
        query = np.column_stack([qi, qj]).astype(np.float64)
        d2 = np.empty((len(parts), len(qi)), dtype=np.int64)
        for k, p in enumerate(parts):  # a few parts
            sel = lab == p
            pi, pj = ci[sel], cj[sel]
            tree = cKDTree(np.column_stack([pi, pj]).astype(np.float64))
            _, near = tree.query(query)
            d2[k] = (qi - pi[near]) ** 2 + (qj - pj[near]) ** 2
        tied = d2 == d2.min(axis=0)
        alone = tied.sum(axis=0) == 1
        low = own + tied[:, alone].sum(axis=1)
        high = low + tied[:, ~alone].sum(axis=1)
        need = _SPLIT_MIN_FRACTION * n_cells
        if ((low >= need) == (high >= need)).all():
            big = np.zeros(n, dtype=bool)
            big[parts - 1] = low >= need
            return big
    markers = np.where(deep[np.maximum(comp - 1, 0)] & (comp > 0), comp, 0)
    _, (ni, nj) = ndimage.distance_transform_edt(markers == 0, return_indices=True)
    owner = markers[ni, nj]  # nearest part of every cell
    area = np.bincount(owner[occ], minlength=n + 1)[1:]
    return deep & (area >= _SPLIT_MIN_FRACTION * n_cells)


def _first_level(
    depth: np.ndarray, levels: list[float], cell: float, radius: float
) -> tuple[int, dict[int, tuple[np.ndarray, int]]]:
    """The index of the first of the ascending levels at which _split_footprint's loop may find
    two deep parts, and the labellings (labels, count) it made, by level index.

    A deep part holds a cell of depth (H, W) >= 1.5 * radius / cell (the set K). At a level t
    below K's shallowest cell, K lies inside the set labelled (depth > t); if K lies in one of
    its components there, it does at every lower level too (their sets hold this one), so those
    levels have at most one deep part. The test labels the highest such level once: a ring of
    noisy walls has a dozen pieces of K, all joined along the wall, and 4-6 levels labelled on
    a room-sized raster are saved. When K is split there, the labels are reused by the loop.
    """
    deep = depth * cell >= 1.5 * radius
    kmin = float(depth[deep].min())
    below = [k for k, t in enumerate(levels) if t < kmin]
    if len(below) < 2:
        return 0, {}
    k = below[-1]
    comp, n = ndimage.label(depth > levels[k], structure=np.ones((3, 3), dtype=bool))
    on_k = comp[deep]
    if n < 2 or (on_k == on_k[0]).all():
        return k + 1, {}
    return 0, {k: (comp, n)}


def _split_footprint(
    xy: np.ndarray, cell: float, radius: float, min_points: int
) -> np.ndarray | None:
    """Part index per point (P,) when the footprint of xy (P, 2) falls apart, else None.

    The footprint raster's depth map (distance of each cell to the footprint's edge) has one
    peak per convex part and a saddle at each neck between parts. Eroding at level t (opening by
    a disc of radius t) cuts every neck shallower than t. A neck is cut when it is shallower than
    ``radius`` (= split_neck_width / 2, the brief's opening), or than _SPLIT_NECK_RATIO times the
    depth of both parts it joins: rasterising fills the cusp between two touching discs, so their
    neck is never thin in absolute terms, only clearly thinner than the discs themselves.
    Parts must each cover _SPLIT_MIN_FRACTION of the footprint and hold min_points points.
    Every footprint cell then goes to the nearest surviving part (the dilation half of the
    opening, without losing the cells an opening would shave off).
    """
    lo = _col(np.minimum, xy)
    shape = np.floor((_col(np.maximum, xy) - lo) / cell).astype(np.int64) + 3  # = ij.max + 2
    if not _may_split(shape, cell, radius):  # too thin to hold a part deep enough
        return None
    # Raster coordinates, also of the power distances below; column by column, as (xy - lo)
    # would run numpy's inner loop over 2 elements.
    ux = (xy[:, 0] - lo[0]) / cell
    uy = (xy[:, 1] - lo[1]) / cell
    occ = np.zeros(tuple(shape), dtype=bool)
    # +1: empty border; truncation = floor (>= 0). One flat index, not a 2-D fancy index.
    occ.reshape(-1)[(ux.astype(np.int64) + 1) * int(shape[1]) + uy.astype(np.int64) + 1] = True
    # Closing bridges the gaps between sample points (a 2 cm lattice on the 1 cm raster).
    # Filling holes makes a side-scanned barrel a disc, not a ring that erosion would wipe out,
    # and removes the speckle of sparse, noisy sampling that would fake saddles. (It also fills
    # the small gap between three barrels touching in a triangle, which then stay one object.)
    occ = _fill_holes(occ | _close3(occ), max_cells=int(_SPLIT_MAX_HOLE / cell**2))
    # The taxicab distance to the edge bounds the Euclidean one from above and costs a tenth:
    # a footprint with no cell deep enough for a part (a ring of walls) stops here.
    if not _taxicab_deep(occ, cell, 1.5 * radius):
        return None
    eight = np.ones((3, 3), dtype=bool)
    n_cells = int(np.count_nonzero(occ))
    depth = _edt_inner(occ, n_cells) - 0.5  # cell centre to footprint edge, cells
    depth[~occ] = 0.0
    top = float(depth.max())
    if top * cell < 1.5 * radius:
        return None  # no part's peak (<= top) can be deep enough at any level of the loop
    # Every level's set (depth > t >= 0.5) lies in the box of the cells deeper than 0.5: the
    # labelling runs there (the same labels: a box keeps the raster order of its cells), not
    # on the whole raster of a room-sized cluster of walls.
    box = _true_box(depth > 0.5)
    depth_box = depth[box]
    # Ascending levels, the shallowest neck is cut first; at most ~40 levels for big footprints.
    levels = []
    for t in np.arange(0.5, top, max(0.5, top / 40.0)):
        if t * cell >= radius and t > _SPLIT_NECK_RATIO * top:
            break  # no part can be deep enough for this level or any higher one (see below)
        levels.append(t)
    first, probed = _first_level(depth_box, levels, cell, radius)
    for k in range(first, len(levels)):
        t = levels[k]
        if k in probed:
            comp_box, n = probed[k]
        else:
            comp_box, n = ndimage.label(depth_box > t, structure=eight)
        if n < 2:
            continue
        inside = comp_box > 0
        peak = np.zeros(n)
        np.maximum.at(peak, comp_box[inside] - 1, depth_box[inside])
        # A part must itself be thicker than the neck that cuts it off: a wall's or a rail's
        # footprint is all neck and stays whole.
        deep = ((t * cell < radius) | (t <= _SPLIT_NECK_RATIO * peak)) & (
            peak * cell >= 1.5 * radius
        )
        if deep.sum() < 2:
            continue
        comp = np.zeros(occ.shape, dtype=comp_box.dtype)
        comp[box] = comp_box
        big = _big_parts(occ, n_cells, comp, deep)
        if big.sum() < 2:
            continue
        # Each point goes to the part of least power distance |p - c|^2 - rho^2, with c, rho
        # the centre and depth of the part's deepest cells (its inscribed disc): for two
        # touching discs the cut is then exactly the tangent at the contact, wherever the
        # raster put the neck. (A cut one cell off moves the many wall points crowding there.)
        keep = np.flatnonzero(big) + 1
        rho = peak[keep - 1]
        ci, cj = np.nonzero(inside)
        ci += box[0].start  # raster indices, as np.nonzero(comp > 0) gives them
        cj += box[1].start
        lab_c = comp[ci, cj]
        top_cells = depth[ci, cj] >= rho[np.searchsorted(keep, lab_c).clip(0, len(keep) - 1)] - 1
        top_cells &= np.isin(lab_c, keep)
        k_of = np.searchsorted(keep, lab_c[top_cells])
        cnt = np.bincount(k_of, minlength=len(keep))
        centre = np.stack(
            [
                np.bincount(k_of, ci[top_cells], minlength=len(keep)) / cnt,
                np.bincount(k_of, cj[top_cells], minlength=len(keep)) / cnt,
            ],
            axis=1,
        )
        vx, vy = ux + 0.5, uy + 0.5  # cell i's centre is at coordinate i
        # (K, P), row by row: the same sums dx^2 + dy^2 as summing a (K, P, 2) array over its
        # last axis, without that array and its strided reduction.
        dist = np.stack(
            [
                (vx - ck[0]) ** 2 + (vy - ck[1]) ** 2 - rk2
                for ck, rk2 in zip(centre, rho**2, strict=True)
            ]
        )
        part = np.argmin(dist, axis=0)
        counts = np.bincount(part, minlength=int(big.sum()))
        if (counts < min_points).any():
            return None
        # Number parts by size so the split does not depend on raster order.
        rank = np.empty(len(counts), dtype=np.int64)
        rank[np.argsort(-counts, kind="stable")] = np.arange(len(counts))
        return rank[part]
    return None


# --------------------------------------------------------------------------------- descriptions


def _order(
    cp: np.ndarray,
    lab: np.ndarray,
    lookups: list[_SupportLookup],
    params: ObjectParams,
    known: np.ndarray | None = None,
) -> Segmentation:
    """Clusters of lab (M,) over cp (M, 3) sorted largest first, their labels renumbered
    accordingly (``labels`` of the result is (M,) here) and their supporting surfaces.

    lookups: the (dilated) footprint lookups of the surfaces the clusters may stand on.
    known: optional (K,) surface of each label found before for the same points (-1: none),
    -2 where it must be found (labels beyond K too).
    """
    out = np.full(len(lab), -1, dtype=np.int64)
    if len(lab) == 0 or lab.max() < 0:
        none = np.zeros((0, 3))
        return Segmentation(out, np.zeros(0, np.int64), none, none.copy())
    n = int(lab.max()) + 1
    # One stable sort by label: each cluster's points are then a contiguous run, in input order.
    grouped = _group_by_label(lab)
    bounds = np.searchsorted(lab[grouped], np.arange(0, n + 1))
    counts = np.diff(bounds)
    present = np.flatnonzero(counts > 0)
    # Ties in size broken by the lowest corner: invariant to point order and to translation.
    mins = np.full((n, 3), np.inf)
    maxs = np.full((n, 3), -np.inf)
    in_clusters = np.take(cp, grouped[bounds[0] :], axis=0)  # all clustered points, by cluster
    mins[present] = _reduce_runs(np.minimum, in_clusters, bounds[present] - bounds[0])
    maxs[present] = _reduce_runs(np.maximum, in_clusters, bounds[present] - bounds[0])
    order = present[
        np.lexsort((mins[present, 2], mins[present, 1], mins[present, 0], -counts[present]))
    ]
    new_id = np.full(n, -1, dtype=np.int64)
    new_id[order] = np.arange(len(order))
    ok = lab >= 0
    out[ok] = new_id[lab[ok]]
    # Each cluster's run of in_clusters, in the new order.
    runs = np.stack([bounds[order] - bounds[0], bounds[order + 1] - bounds[0]], axis=1)
    if known is None:
        groups = [in_clusters[a:b] for a, b in runs.tolist()]  # one slice per cluster
        sids = _supports(groups, lookups, params.support_tolerance)
    else:
        sids = np.full(len(order), -2, dtype=np.int64)
        have = order < len(known)
        sids[have] = known[order[have]]
        todo = np.flatnonzero(sids == -2)
        # A cluster's surface depends on its points alone: only the new ones are looked up.
        groups = [in_clusters[a:b] for a, b in runs[todo].tolist()]  # one slice per cluster
        sids[todo] = _supports(groups, lookups, params.support_tolerance)
    return Segmentation(
        out,
        sids,
        mins[order],
        maxs[order],
        _grouped=in_clusters,
        _runs=runs,
        _heights={lk.id: lk.height for lk in lookups},
    )


def _describe(seg: Segmentation, memo: Memo | None = None) -> list[Cluster]:
    """Hulls, oriented boxes and heights of the clusters of seg, in its order."""
    if len(seg.surface_ids) == 0:
        return []
    runs = seg._runs.tolist()
    groups = [seg._grouped[a:b] for a, b in runs]  # one slice per cluster
    # Coordinates as rows (3, P): each cluster's centroid is then one cumsum along contiguous
    # rows (see _make_cluster).
    rows = np.ascontiguousarray(seg._grouped.T)
    lo, hi = seg.bbox_min, seg.bbox_max  # bounding boxes: the same min / max as per cluster
    if memo is None:
        hulls = [_hulls(p, lo[cid], hi[cid]) for cid, p in enumerate(groups)]  # per cluster
    else:  # lo, hi are p's own bounds: a pure function of p
        hulls = [
            memo.get("hull", p, lambda p=p, cid=cid: _hulls(p, lo[cid], hi[cid]))
            for cid, p in enumerate(groups)
        ]  # per cluster
    # The hulls, never the raw points: the edge search is quadratic in the vertices.
    rects = _oriented_rects([footprint for footprint, _ in hulls])
    return [
        _make_cluster(
            cid,
            rows[:, runs[cid][0] : runs[cid][1]],
            lo[cid],
            hi[cid],
            None if sid < 0 else int(sid),
            seg._heights,
            hull,
            rect,
        )
        for cid, (sid, hull, rect) in enumerate(
            zip(seg.surface_ids.tolist(), hulls, rects, strict=True)
        )  # per cluster
    ]


def _group_by_label(lab: np.ndarray) -> np.ndarray:
    """``np.argsort(lab, kind="stable")`` of labels lab (M,) >= -1, as a radix sort when the
    labels fit in 16 bits (the same permutation: a stable sort of equal keys is unique), which
    is 10x faster than the comparison sort numpy uses for int64 keys."""
    if len(lab) and lab.max() < np.iinfo(np.uint16).max:
        return np.argsort((lab + 1).astype(np.uint16), kind="stable")
    return np.argsort(lab, kind="stable")


def _reduce_runs(ufunc: np.ufunc, a: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """ufunc.reduce over the row runs of a (P, D) starting at starts (R,): (R, D).

    Column by column: numpy reduces (P, 3) arrays along axis 0 10-30x slower than 1-D ones.
    """
    return np.stack([ufunc.reduceat(a[:, j], starts) for j in range(a.shape[1])], axis=1)


def _percentile(a: np.ndarray, q: float) -> float:
    """``float(np.percentile(a, q))`` (method 'linear') of a non-empty 1-D float array: the same
    arithmetic, without the 40 us of numpy's generic quantile machinery per call."""
    n = len(a)
    v = (n - 1) * (q / 100)  # numpy's virtual index
    i = int(v) if v < n - 1 else -1  # floor; numpy's index -1 (the maximum) past the end
    # numpy's kth, not just (i, i + 1): equal values (0.0 and -0.0) then land alike.
    part = np.partition(a, np.unique([0, -1, i, i + 1 if i >= 0 else -1]))
    lo, hi = float(part[i]), float(part[i + 1 if i >= 0 else -1])
    t = v - i
    d = hi - lo
    # numpy's _lerp: from the nearer end, so t = 1 gives hi exactly.
    return hi - d * (1 - t) if t >= 0.5 else lo + d * t


def _col(ufunc: np.ufunc, a: np.ndarray) -> np.ndarray:
    """``ufunc.reduce(a, axis=0)`` of a (P, D) array, column by column (same values, faster)."""
    return np.array([ufunc.reduce(a[:, j]) for j in range(a.shape[1])])


def _fill_holes(mask: np.ndarray, max_cells: int | None = None) -> np.ndarray:
    """``ndimage.binary_fill_holes(mask)`` for a 2-D mask, by one labelling of the background;
    with ``max_cells``, only holes of at most that many cells are filled.

    Holes are the 4-connected background components that do not touch the array's edge, as in
    binary_fill_holes, whose iterated dilation from the edge is 3-4x slower on big rasters.
    A large raster with no hole at all (see _hole_count) is returned as it is (mask itself).
    """
    if mask.size >= _FILL_CHECK_MIN_CELLS and _hole_count(mask) == 0:
        return mask
    lab, n = ndimage.label(~mask)
    outside = np.zeros(n + 1, dtype=bool)
    for edge in (lab[0], lab[-1], lab[:, 0], lab[:, -1]):  # the four edges of the raster
        outside[edge] = True
    if max_cells is not None:
        outside |= np.bincount(lab.ravel(), minlength=n + 1) > max_cells
    outside[0] = False  # label 0 is the mask itself
    return ~outside[lab]


def _hole_count(mask: np.ndarray) -> int:
    """Number of holes of a 2-D bool mask, as _fill_holes counts them: 4-connected background
    components that do not touch the edge.

    By the Euler number of the 8-connected foreground (components minus holes, from the 2 x 2
    windows of the zero-padded mask, Gray 1971): the holes are the bounded background
    components of the padded plane, exactly those that do not touch the edge. Labelling the
    sparse foreground of a wall cluster's footprint costs half as much as labelling its
    background.
    """
    q = np.pad(mask, 1).view(np.uint8)
    a, d = q[:-1, :-1], q[1:, 1:]
    s = a + q[:-1, 1:] + q[1:, :-1] + d  # foreground cells in each 2 x 2 window
    n1 = np.count_nonzero(s == 1)
    n3 = np.count_nonzero(s == 3)
    n_diag = np.count_nonzero((s == 2) & (a == d))  # two cells on a diagonal
    euler = (n1 - n3 - 2 * n_diag) // 4
    _, n_comp = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    return n_comp - euler


def _close3(mask: np.ndarray) -> np.ndarray:
    """``ndimage.binary_closing(mask, np.ones((3, 3)))`` of a 2-D bool mask (outside = empty).

    As separable ORs then ANDs of shifted slices: scipy's closing (or max then min filters)
    costs 5-10x more on the large, nearly empty footprint rasters of wall clusters.
    """
    h, w = mask.shape
    pad = np.zeros((h + 4, w + 4), dtype=bool)
    pad[2:-2, 2:-2] = mask
    dil = pad[:-2] | pad[1:-1] | pad[2:]
    dil = dil[:, :-2] | dil[:, 1:-1] | dil[:, 2:]  # (h + 2, w + 2): one ring beyond the raster
    # The erosion sees the outside as empty (border_value=0), whatever the dilation put there.
    dil[0] = dil[-1] = False
    dil[:, 0] = dil[:, -1] = False
    ero = dil[:-2] & dil[1:-1] & dil[2:]
    return ero[:, :-2] & ero[:, 1:-1] & ero[:, 2:]


def _taxicab_deep(mask: np.ndarray, cell: float, limit: float) -> bool:
    """Whether ``(distance_transform_cdt(mask, "taxicab").max() - 0.5) * cell >= limit`` for a
    2-D bool mask whose outer rows and columns are empty.

    A cell is at taxicab distance >= k from the background iff it survives k - 1 erosions by
    the 4-neighbour cross; the expression grows with k, so erosion stops at the first k that
    reaches limit (a few erosions) or when nothing is left (then k - 1 was the maximum).
    """
    cur, k = mask, 1
    while cur.any():  # some cell is at distance >= k
        if (k - 0.5) * cell >= limit:
            return True
        ero = np.zeros_like(cur)
        ero[1:-1, 1:-1] = (
            cur[1:-1, 1:-1] & cur[:-2, 1:-1] & cur[2:, 1:-1] & cur[1:-1, :-2] & cur[1:-1, 2:]
        )
        cur, k = ero, k + 1
    return False


def _true_box(mask: np.ndarray) -> tuple[slice, slice]:
    """The smallest box (row slice, column slice) holding the True cells of a 2-D bool mask;
    the whole mask when it has none."""
    rows = np.flatnonzero(mask.any(axis=1))
    if len(rows) == 0:
        return slice(0, mask.shape[0]), slice(0, mask.shape[1])
    cols = np.flatnonzero(mask.any(axis=0))
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def _edt_inner(mask: np.ndarray, count: int | None = None) -> np.ndarray:
    """``ndimage.distance_transform_edt(mask)`` (H, W) float64, cells, of a 2-D bool mask whose
    outer rows and columns are empty; the same values. count: ``mask.sum()`` when known.

    A room-sized cluster of walls has a big, nearly empty footprint raster, where scipy's
    transform costs ~40 ns per cell (5-12 ms). On a raster of at least _EDT_SPARSE_MIN_CELLS
    cells, at most _EDT_SPARSE_MAX_FILL of them occupied, the distance is taken at the occupied
    cells only, separably: the distance to the nearest empty cell in the same column (from the
    column's runs of occupied cells), then the least ``g(i, j +- d)^2 + d^2`` over growing
    column offsets d, each cell dropping out once d^2 reaches its best. That minimum is the
    exact squared distance, an integer; its sqrt is what scipy takes of the same integer.
    """
    h, w = mask.shape
    if count is None:
        count = int(np.count_nonzero(mask))
    if mask.size < _EDT_SPARSE_MIN_CELLS or count > _EDT_SPARSE_MAX_FILL * mask.size:
        return ndimage.distance_transform_edt(mask)
    out = np.zeros(h * w)
    if count == 0:
        return out.reshape(h, w)
    # Column-major flat indices j * h + i: a run of consecutive ones is a run down a column,
    # never across two (the first and last rows are empty).
    cm = np.flatnonzero(mask.T)
    brk = np.empty(len(cm), dtype=bool)
    brk[0] = True
    np.not_equal(cm[1:], cm[:-1] + 1, out=brk[1:])
    start = np.flatnonzero(brk)
    length = np.diff(start, append=len(cm))
    pos = np.arange(len(cm)) - np.repeat(start, length)  # 0 at a run's first cell
    g = np.minimum(pos + 1, np.repeat(length, length) - pos)  # to the empty cell above / below
    j, i = np.divmod(cm, h)
    flat = i * w + j
    col_dist = np.zeros(h * w, dtype=np.int32)  # 0 at empty cells; int32: fewer pages touched
    col_dist[flat] = g
    d2 = g * g
    # Offset d never reaches past the empty first or last column: a cell d columns from it has
    # d2 <= d^2 and drops out before.
    cand = np.flatnonzero(d2 > 1)
    d = 1
    while len(cand):
        f = flat[cand]
        near = np.minimum(col_dist[f - d], col_dist[f + d]).astype(np.int64)
        best = np.minimum(d2[cand], near * near + d * d)
        d2[cand] = best
        d += 1
        cand = cand[best > d * d]  # offsets >= d give at least d^2
    out[flat] = np.sqrt(d2.astype(np.float64))
    return out.reshape(h, w)


class _CellIndex:
    """``floor(xy / cell)`` of fixed points (P, 2) m, computed once per cell size (C, 2) m."""

    def __init__(self, xy: np.ndarray) -> None:
        self.xy = xy
        self._cache: dict[tuple[float, float], np.ndarray] = {}

    def of(self, cell: np.ndarray) -> np.ndarray:
        """(P, 2) int64 cell indices of the points on the grid of size cell (2,) m."""
        key = (float(cell[0]), float(cell[1]))
        if key not in self._cache:
            self._cache[key] = np.floor(self.xy / cell).astype(np.int64)
        return self._cache[key]


class _SupportLookup:
    """Dense footprint raster of one surface for point-over-surface queries."""

    def __init__(self, surface: Surface, dilate: bool = True) -> None:
        self.id = surface.id
        self.height = float(surface.height)
        self.cell = np.asarray(surface.cell_size, dtype=np.float64)
        cells = np.asarray(surface.cells, dtype=np.int64).reshape(-1, 2)
        if len(cells) == 0:
            self.mask = np.zeros((1, 1), dtype=bool)
            self.origin = np.zeros(2, dtype=np.int64)
            return
        # One cell of border, then: holes filled (the cells under an object on a table hold no
        # table points, yet the table is under it) and one cell of dilation (an object at the edge
        # of a table sits in a notch of the footprint).
        self.origin = cells.min(axis=0) - 1
        rel = cells - self.origin
        mask = np.zeros(tuple(rel.max(axis=0) + 2), dtype=bool)
        mask[rel[:, 0], rel[:, 1]] = True
        mask = _fill_holes(mask)
        if dilate:
            mask = ndimage.binary_dilation(mask, structure=np.ones((3, 3), dtype=bool))
        self.mask = mask

    def dilated(self) -> _SupportLookup:
        """This lookup with its footprint dilated by one cell, as ``dilate=True`` builds it."""
        out = copy.copy(self)
        out.mask = ndimage.binary_dilation(self.mask, structure=np.ones((3, 3), dtype=bool))
        return out

    def over_cells(self, ij: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """(P,) bool: which points lie over this surface's (filled) footprint, from their
        cells ij (P, 2) int64 = floor(xy / self.cell); or (Q,) for the rows ``rows`` of ij."""
        i = ij[:, 0] if rows is None else ij[rows, 0]
        j = ij[:, 1] if rows is None else ij[rows, 1]
        i = i - self.origin[0]
        j = j - self.origin[1]
        h, w = self.mask.shape
        # One unsigned comparison per axis tests 0 <= i < h (negatives wrap to huge values).
        inside = (i.astype(np.uint64) < h) & (j.astype(np.uint64) < w)
        res = np.zeros(len(i), dtype=bool)
        res[inside] = self.mask[i[inside], j[inside]]
        return res


def _supports(groups: list[np.ndarray], lookups: list[_SupportLookup], tol: float) -> np.ndarray:
    """(C,) int64: the surface id under the lowest points of each cluster (P_c, 3), -1 for none.

    The lowest points of every cluster are tested against each surface once (a loop over
    surfaces, not over cluster-surface pairs). A cluster stands on the surface over which the
    largest fraction of its lowest points lie (at least _SUPPORT_MIN_FRACTION), ties to the
    surface closest in height, then to the lowest id.
    """
    n = len(groups)
    best = np.full(n, -1, dtype=np.int64)
    if n == 0 or not lookups:
        return best
    bottom = np.empty(n)
    low = []
    for c, p in enumerate(groups):  # one iteration per cluster
        z = p[:, 2]
        # A robust bottom: one stray low point must not decide what the cluster stands on.
        bottom[c] = _percentile(z, 1.0) if len(z) >= 100 else float(z.min())
        low.append(p[z <= bottom[c] + _BOTTOM_BAND, :2])
    n_low = np.array([len(q) for q in low])
    owner = np.repeat(np.arange(n), n_low)
    low_xy = np.concatenate(low)
    starts = np.cumsum(n_low) - n_low
    cells = _CellIndex(low_xy)
    best_frac = np.full(n, -np.inf)
    best_gap = np.full(n, -np.inf)
    for lk in lookups:  # one iteration per surface
        gap = bottom - lk.height
        # Surface points within point_tolerance were removed, so object bottoms start a little
        # above the surface; noise may put them a little below.
        near = np.flatnonzero((-tol <= gap) & (gap <= tol))
        if len(near) == 0:
            continue
        rows = np.concatenate([np.arange(starts[c], starts[c] + n_low[c]) for c in near])
        hits = lk.over_cells(cells.of(lk.cell), rows)
        count = np.bincount(owner[rows], weights=hits, minlength=n)[near]
        frac = count / n_low[near]  # the mean of the booleans, exactly
        key_gap = -np.abs(gap[near])
        # Lexicographic (frac, -|gap|, -id) as before, compared with the best so far.
        better = (frac > best_frac[near]) | (
            (frac == best_frac[near])
            & (
                (key_gap > best_gap[near])
                | ((key_gap == best_gap[near]) & ((best[near] < 0) | (lk.id < best[near])))
            )
        )
        take = near[better & (frac >= _SUPPORT_MIN_FRACTION)]
        sel = better & (frac >= _SUPPORT_MIN_FRACTION)
        best[take] = lk.id
        best_frac[take] = frac[sel]
        best_gap[take] = key_gap[sel]
    return best


def _make_cluster(
    cid: int,
    rows: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    sid: int | None,
    height_of: dict[int, float],
    hull: tuple[np.ndarray, float],
    rect: tuple[np.ndarray, float, float, float],
) -> Cluster:
    """Properties of one cluster standing on surface sid (heights by surface id).

    rows: the cluster's points transposed (3, P), C-contiguous; lo, hi: (3,) their bounding
    box; hull: footprint and volume (see _hulls); rect: oriented box of the footprint (see
    _oriented_rect).
    """
    base = height_of[sid] if sid is not None else lo[2]
    footprint, volume = hull
    centre_xy, length, width, yaw = rect
    n = rows.shape[1]
    return Cluster(
        id=cid,
        surface_id=sid,
        point_count=n,
        # p.mean(axis=0) sums each column in point order (not pairwise); so does cumsum, 3x
        # faster along contiguous rows: the same bits.
        centroid=np.cumsum(rows, axis=1)[:, -1] / n,
        bbox_min=lo,
        bbox_max=hi,
        obb_center=np.array([centre_xy[0], centre_xy[1], (lo[2] + hi[2]) / 2]),
        obb_size=np.array([length, width, hi[2] - lo[2]]),
        obb_yaw=yaw,
        height=float(hi[2] - base),
        footprint=footprint,
        volume=volume,
    )


def _hulls(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, float]:
    """x, y footprint (K, 2) (see _hull_2d) and convex-hull volume (m^3) of p (P, 3).

    lo, hi: (3,) bounding box of p. The footprint is the 2-D hull of the 3-D hull's vertices
    only: projecting a convex hull gives the hull of the projected vertices, and the 3-D hull
    has a few dozen vertices where a wall cluster has 80k points.
    """
    volume, verts = 0.0, None
    # A set flat along an axis has no volume; Qhull would raise (slowly) on it.
    if len(p) >= 4 and (hi > lo).all():
        q = np.compress(_column_ends(p), p, axis=0) if len(p) >= _COLUMN_DEDUPE_MIN else p
        try:
            hull = ConvexHull(q)
            # hull.vertices is np.unique(hull.simplices): a mask keeps the same rows in the
            # same (input) order without the sort.
            used = np.zeros(len(q), dtype=bool)
            used[hull.simplices] = True
            volume, verts = float(hull.volume), np.compress(used, q, axis=0)
        except (QhullError, ValueError):
            pass
    if not (hi[:2] > lo[:2]).all():
        # All on one line x = c or y = c (a wall strip seen edge-on): what _hull_2d returns
        # for collinear sets, its two ends in sorted order (or the one point), without the
        # failed Qhull call and the sort of all points.
        ends = np.array([lo[:2], hi[:2]])
        return (ends[:1] if (ends[0] == ends[1]).all() else ends), volume
    return _hull_2d(p[:, :2] if verts is None else verts[:, :2]), volume


def _oriented_rect(xy: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """Yaw-only box around xy (K, 2): (centre (2,), length, width, yaw of the length axis).

    For a hull polygon, the minimum-area rectangle (one side is flush with a hull edge, so only
    the K edge directions are tried); PCA of the spread would be arbitrary for a square footprint
    and too wide for a cylinder next to a box. Degenerate sets use the principal axis.
    """
    if len(xy) >= 3:
        edges = np.concatenate([xy[1:], xy[:1]]) - xy  # np.roll(xy, -1, axis=0) - xy
        angles = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2)
    else:
        d = xy - xy.mean(axis=0)
        _, vec = np.linalg.eigh(d.T @ d)
        angles = np.array([np.mod(np.arctan2(vec[1, 1], vec[0, 1]), np.pi / 2)])
    cos, sin = np.cos(angles), np.sin(angles)
    u = xy[:, 0, None] * cos + xy[:, 1, None] * sin  # (K, A): coordinate along each direction
    v = -xy[:, 0, None] * sin + xy[:, 1, None] * cos
    ext_u = u.max(axis=0) - u.min(axis=0)
    ext_v = v.max(axis=0) - v.min(axis=0)
    best = int(np.argmin(ext_u * ext_v + 1e-12 * angles))  # ties: the smallest angle
    a, c, s = angles[best], cos[best], sin[best]
    mu = (u[:, best].max() + u[:, best].min()) / 2
    mv = (v[:, best].max() + v[:, best].min()) / 2
    centre = np.array([mu * c - mv * s, mu * s + mv * c])
    length, width = float(ext_u[best]), float(ext_v[best])
    if width > length:
        length, width, a = width, length, a + np.pi / 2
    if a > np.pi / 2:
        a -= np.pi  # yaw in (-pi/2, pi/2]
    return centre, length, width, float(a)


def _oriented_rects(polys: list[np.ndarray]) -> list[tuple[np.ndarray, float, float, float]]:
    """:func:`_oriented_rect` of each polygon of polys (K_i, 2), the same values.

    Polygons of 3 to _RECT_BATCH_MAX vertices go in one batch: each is padded to the largest
    K with copies of its last vertex (which change no extent) and its padded directions are
    never chosen; every value comes from the same element-wise operations as one at a time,
    without some 20 numpy calls per cluster. Others (degenerate, or so large that padding all
    to them would cost more) are done one by one.
    """
    out: list = [None] * len(polys)
    k = np.array([len(xy) for xy in polys], dtype=np.int64)
    batch = np.flatnonzero((k >= 3) & (k <= _RECT_BATCH_MAX))
    for i in np.flatnonzero((k < 3) | (k > _RECT_BATCH_MAX)):
        out[i] = _oriented_rect(polys[i])
    if len(batch) == 0:
        return out
    kb = k[batch]
    starts = np.cumsum(kb) - kb
    xy = np.concatenate([polys[i] for i in batch])  # (N, 2)
    t = np.arange(int(kb.max()))
    # Row t of polygon j, or its last vertex past the end: (B, T) flat indices into xy.
    idx = starts[:, None] + np.minimum(t[None, :], kb[:, None] - 1)
    nxt = np.arange(len(xy)) + 1
    nxt[starts + kb - 1] = starts  # each polygon's last vertex closes onto its first
    edges = np.take(xy, nxt, axis=0) - xy  # (N, 2), as np.roll(xy, -1, axis=0) - xy
    flat = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2)
    angles, cos, sin = flat[idx], np.cos(flat)[idx], np.sin(flat)[idx]  # (B, T)
    x, y = xy[idx, 0][:, :, None], xy[idx, 1][:, :, None]  # (B, T, 1): vertex along axis 1
    u = x * cos[:, None, :] + y * sin[:, None, :]  # (B, T, A)
    v = -x * sin[:, None, :] + y * cos[:, None, :]
    u_max, u_min = u.max(axis=1), u.min(axis=1)
    v_max, v_min = v.max(axis=1), v.min(axis=1)
    ext_u, ext_v = u_max - u_min, v_max - v_min  # (B, A)
    score = ext_u * ext_v + 1e-12 * angles
    score[t[None, :] >= kb[:, None]] = np.inf  # padded directions
    best = np.argmin(score, axis=1)  # ties: the smallest angle, as _oriented_rect
    rb = np.arange(len(batch))
    a, c, s = angles[rb, best], cos[rb, best], sin[rb, best]
    mu = (u_max[rb, best] + u_min[rb, best]) / 2
    mv = (v_max[rb, best] + v_min[rb, best]) / 2
    centre = np.stack([mu * c - mv * s, mu * s + mv * c], axis=1)
    length, width = ext_u[rb, best], ext_v[rb, best]
    swap = width > length
    length, width = np.where(swap, width, length), np.where(swap, length, width)
    a = np.where(swap, a + np.pi / 2, a)
    a = np.where(a > np.pi / 2, a - np.pi, a)  # yaw in (-pi/2, pi/2]
    for j, i in enumerate(batch.tolist()):
        out[i] = (centre[j], float(length[j]), float(width[j]), float(a[j]))
    return out


def _column_ends(p: np.ndarray) -> np.ndarray:
    """(P,) bool: the points of p (P, 3) that may be hull vertices, as far as columns tell.

    A point strictly between two points of exactly the same x, y lies on the vertical segment
    joining them and is never a vertex of the convex hull, so dropping it changes neither the
    hull nor its volume (up to round-off in the facet sums). Scanners put many points on one
    vertical line (the beams of one azimuth on a wall: 80k points on 2.7k lines in the
    simulator's kitchen); for others nothing is dropped. The points are grouped by a 32-bit
    hash of their x, y bits with two 16-bit radix passes (a comparison sort of 80k keys takes
    10x longer); a hash collision only splits a line's points into runs and keeps more.
    """
    bits = np.ascontiguousarray(p).view(np.uint64)  # (P, 3): x, y columns read in place
    x, y = bits[:, 0], bits[:, 1]
    h = (((x * _HASH_X) ^ (y * _HASH_Y)) >> np.uint64(32)).astype(np.uint32)
    order = np.argsort(h.astype(np.uint16), kind="stable")  # low 16 bits, then high 16
    order = order[np.argsort((h >> np.uint32(16)).astype(np.uint16)[order], kind="stable")]
    xs, ys = np.take(x, order), np.take(y, order)
    new_line = np.empty(len(p), dtype=bool)
    new_line[0] = True
    np.not_equal(xs[1:], xs[:-1], out=new_line[1:])
    new_line[1:] |= ys[1:] != ys[:-1]
    first = np.flatnonzero(new_line)
    run = np.diff(first, append=len(p))
    z = np.take(p[:, 2], order)
    # Each line's extremes repeated over its run: cheaper than a cumsum of line ids and gathers.
    inner = (z > np.repeat(np.minimum.reduceat(z, first), run)) & (
        z < np.repeat(np.maximum.reduceat(z, first), run)
    )
    keep = np.empty(len(p), dtype=bool)
    keep[order] = ~inner
    return keep


def _hull_2d(xy: np.ndarray) -> np.ndarray:
    """Convex hull (K, 2) of xy, counter-clockwise; the distinct points for degenerate sets."""
    try:
        hull = ConvexHull(xy)
    except (QhullError, ValueError):
        uniq = np.unique(xy, axis=0)
        if len(uniq) <= 2:
            return uniq
        # Collinear: the two extreme points along the line.
        d = uniq - uniq[0]
        t = d @ (d[np.argmax((d**2).sum(axis=1))])
        return uniq[[np.argmin(t), np.argmax(t)]]
    return xy[hull.vertices]  # scipy gives 2-D hull vertices counter-clockwise
