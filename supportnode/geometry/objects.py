"""Supported objects: clusters of the points that lie on no support surface.

Two methods share one result type:
- ``knn``: Algorithm 2 of the report as published. Sample a fraction ``s`` of the candidates, link
  two samples when either is among the other's ``k`` nearest neighbours, take connected components;
  every candidate then takes the label of its nearest sample within ``label_radius``.
- ``voxel`` (default, the report's own suggestion): 26-connected components of the occupied voxels
  of a fine grid. No sampling, so no seed and no lost thin parts; linear in the number of points.

Both may then split *touching* objects (the report's main error: barrels side by side merged): a
cluster whose x, y footprint falls apart into large parts under a morphological opening of radius
``split_neck_width / 2`` is cut along the neck. Clusters are never split vertically (a stack of boxes
is one object in the simulator's ground truth).

Each cluster is then attached to the surface directly under its lowest points, if any.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree

from supportnode.errors import InputError
from supportnode.geometry.surfaces import Surface, SurfaceResult
from supportnode.params import ObjectParams

__all__ = ["Cluster", "ObjectResult", "detect_objects"]

# Points within this of a cluster's (robust) bottom are its "lowest points" for the support lookup.
_BOTTOM_BAND = 0.02
# A split part must hold at least this fraction of the cluster's footprint cells.
_SPLIT_MIN_FRACTION = 0.15
# A neck this much shallower than both parts it joins is cut (see _split_footprint).
_SPLIT_NECK_RATIO = 0.6
# Footprint raster cell = voxel_size / this (1 cm at the default 3 cm voxels).
_SPLIT_CELL_DIVISOR = 3.0
# Recursion depth of splitting: up to 2**depth parts per cluster.
_SPLIT_DEPTH = 3
# A cluster stands on a surface when at least this fraction of its lowest points are over it.
_SUPPORT_MIN_FRACTION = 0.5


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
        }


@dataclass
class ObjectResult:
    """Clusters sorted largest first (ids 0, 1, ... in that order) and a label per input point."""

    clusters: list[Cluster]
    labels: np.ndarray  # (N,) int32: cluster id of each input point, -1 for none
    stats: dict = field(default_factory=dict)


def detect_objects(
    points: np.ndarray, surfaces: SurfaceResult, params: ObjectParams | None = None
) -> ObjectResult:
    """Cluster the points that lie on no surface into objects.

    points: (N, 3) float, metres, z up. surfaces: the result of surface detection on the same
    points (``surfaces.labels`` is (N,), -1 for the candidates clustered here).
    Returns clusters sorted by point count (ties broken by position, so the result does not depend
    on point order) and (N,) int32 labels, -1 for surface points, noise and unlabelled points.
    Raises InputError on a wrong shape, non-finite values or a label array of the wrong length.
    """
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
    cp = pts[cand]
    stats: dict = {"method": params.method, "candidates": len(cand)}
    if params.method == "knn":
        lab = _cluster_knn(cp, params, stats)
    elif params.method == "voxel":
        support = _support_below(cp, surfaces.surfaces, params.support_tolerance)
        lab = _cluster_voxel(cp, params.voxel_size, stats, support)
    else:
        raise InputError(f"unknown object method {params.method!r}; expected 'knn' or 'voxel'")
    lab = _drop_small(lab, params.min_points)
    stats["components"] = int(lab.max() + 1) if len(lab) else 0
    t1 = time.perf_counter()

    stats["merged_splits"] = 0  # clusters cut into parts at a thin footprint neck
    stats["split_parts"] = 0
    if params.split_touching and len(lab):
        lab = _split_touching(cp, lab, params, stats)
    t2 = time.perf_counter()

    clusters, lab = _describe(cp, lab, surfaces.surfaces, params)
    labels = np.full(len(pts), -1, dtype=np.int32)
    labels[cand] = lab
    stats["clusters"] = len(clusters)
    stats["labelled_points"] = int((lab >= 0).sum())
    stats["time_cluster_s"] = t1 - t0
    stats["time_split_s"] = t2 - t1
    stats["time_describe_s"] = time.perf_counter() - t2
    return ObjectResult(clusters=clusters, labels=labels, stats=stats)


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


# The 13 "forward" offsets of the 26-neighbourhood: each undirected voxel pair is tested once.
_FORWARD = np.array(
    [
        (dx, dy, dz)
        for dx in (-1, 0, 1)
        for dy in (-1, 0, 1)
        for dz in (-1, 0, 1)
        if (dx, dy, dz) > (0, 0, 0)
    ],
    dtype=np.int64,
)


def _support_below(cp: np.ndarray, surfaces: list[Surface], tol: float) -> np.ndarray:
    """(M,) int64: the highest surface under each point of cp (M, 3), -1 when none.

    A point is over a surface when its x, y falls on the surface's (filled) footprint and it is
    no more than ``tol`` below the surface's height.
    """
    sup = np.full(len(cp), -1, dtype=np.int64)
    ordered = sorted(surfaces, key=lambda s: s.height)
    # The ground (lowest surface with nothing below it) is dilated: a wall standing on its
    # ragged edge would otherwise alternate between "over the floor" and "over nothing" and
    # fall into strips.
    ground = (
        ordered[0] if ordered and len(cp) and cp[:, 2].min() >= ordered[0].height - tol else None
    )
    for s in ordered:  # higher surfaces overwrite lower ones
        # Undilated: a chair back rising just beside a table must not be cut at table height.
        lk = _SupportLookup(s, dilate=s is ground)
        above = cp[:, 2] >= lk.height - tol
        idx = np.flatnonzero(above)
        sup[idx[lk.over(cp[idx, :2])]] = lk.id
    return sup


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
    ijk = np.floor((cp - cp.min(axis=0)) / voxel_size).astype(np.int64) + 1
    dims = ijk.max(axis=0) + 2
    strides = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
    keys = ijk @ strides
    vkeys, inv = np.unique(keys, return_inverse=True)
    nv = len(vkeys)
    stats["voxels"] = int(nv)
    rows, cols = [], []
    for off in _FORWARD @ strides:  # 13 vectorised look-ups, not a loop over voxels
        pos = np.searchsorted(vkeys, vkeys + off)
        pos = np.minimum(pos, nv - 1)
        hit = np.flatnonzero(vkeys[pos] == vkeys + off)
        rows.append(hit)
        cols.append(pos[hit])
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
    uniq, inv, counts = np.unique(lab[ok], return_inverse=True, return_counts=True)
    keep = counts >= min_points
    new_id = np.full(len(uniq), -1, dtype=np.int64)
    new_id[keep] = np.arange(int(keep.sum()))
    out[ok] = new_id[inv.ravel()]
    return out


# ------------------------------------------------------------------------------ touching objects


def _split_touching(
    cp: np.ndarray, lab: np.ndarray, params: ObjectParams, stats: dict
) -> np.ndarray:
    """Cut clusters whose x, y footprint has large parts joined by a neck (see _split_footprint)."""
    cell = params.voxel_size / _SPLIT_CELL_DIVISOR
    radius = params.split_neck_width / 2.0
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(-1, lab.max() + 2))
    out = lab.copy()
    next_id = int(lab.max()) + 1
    for c in range(int(lab.max()) + 1):  # one iteration per cluster, vectorised inside
        idx = order[bounds[c + 1] : bounds[c + 2]]
        parts = _split_recursive(cp[idx, :2], cell, radius, params.min_points, _SPLIT_DEPTH)
        n_parts = int(parts.max()) + 1
        if n_parts < 2:
            continue
        stats["merged_splits"] += 1
        stats["split_parts"] += n_parts
        # Part 0 keeps the cluster's id; the others take fresh ids (ids are re-sorted later).
        rest = parts > 0
        out[idx[rest]] = next_id + parts[rest] - 1
        next_id += n_parts - 1
    return out


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
        sub = _split_recursive(xy[sel], cell, radius, min_points, depth - 1)
        out[sel] = sub + n
        n += int(sub.max()) + 1
    return out


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
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64) + 1  # +1: empty border
    shape = tuple(ij.max(axis=0) + 2)
    if min(shape) < 5:  # too thin to hold two parts of any depth
        return None
    occ = np.zeros(shape, dtype=bool)
    occ[ij[:, 0], ij[:, 1]] = True
    # Closing bridges the gaps between sample points (a 2 cm lattice on the 1 cm raster).
    # Filling holes makes a side-scanned barrel a disc, not a ring that erosion would wipe out,
    # and removes the speckle of sparse, noisy sampling that would fake saddles. (It also fills
    # the small gap between three barrels touching in a triangle, which then stay one object.)
    eight = np.ones((3, 3), dtype=bool)
    occ = ndimage.binary_fill_holes(occ | ndimage.binary_closing(occ, eight, border_value=0))
    n_cells = int(occ.sum())
    depth = ndimage.distance_transform_edt(occ) - 0.5  # cell centre to footprint edge, cells
    depth[~occ] = 0.0
    top = float(depth.max())
    # Ascending levels, the shallowest neck is cut first; at most ~40 levels for big footprints.
    for t in np.arange(0.5, top, max(0.5, top / 40.0)):
        comp, n = ndimage.label(depth > t, structure=eight)
        if n < 2:
            continue
        inside = comp > 0
        peak = np.zeros(n)
        np.maximum.at(peak, comp[inside] - 1, depth[inside])
        # A part must itself be thicker than the neck that cuts it off: a wall's or a rail's
        # footprint is all neck and stays whole.
        deep = ((t * cell < radius) | (t <= _SPLIT_NECK_RATIO * peak)) & (
            peak * cell >= 1.5 * radius
        )
        if deep.sum() < 2:
            continue
        markers = np.where(deep[np.maximum(comp - 1, 0)] & (comp > 0), comp, 0)
        _, (ni, nj) = ndimage.distance_transform_edt(markers == 0, return_indices=True)
        owner = markers[ni, nj]  # nearest part of every cell
        area = np.bincount(owner[occ], minlength=n + 1)[1:]
        big = deep & (area >= _SPLIT_MIN_FRACTION * n_cells)
        if big.sum() < 2:
            continue
        # Each point goes to the part of least power distance |p - c|^2 - rho^2, with c, rho
        # the centre and depth of the part's deepest cells (its inscribed disc): for two
        # touching discs the cut is then exactly the tangent at the contact, wherever the
        # raster put the neck. (A cut one cell off moves the many wall points crowding there.)
        keep = np.flatnonzero(big) + 1
        rho = peak[keep - 1]
        ci, cj = np.nonzero(comp > 0)
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
        uv = (xy - xy.min(axis=0)) / cell + 0.5  # cell i's centre is at coordinate i
        dist = ((uv[None, :, :] - centre[:, None, :]) ** 2).sum(axis=2) - (rho**2)[:, None]
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


def _describe(
    cp: np.ndarray, lab: np.ndarray, surfaces: list[Surface], params: ObjectParams
) -> tuple[list[Cluster], np.ndarray]:
    """Sort clusters largest first, renumber lab accordingly, and describe each cluster."""
    out = np.full(len(lab), -1, dtype=np.int64)
    if len(lab) == 0 or lab.max() < 0:
        return [], out
    n = int(lab.max()) + 1
    ok = lab >= 0
    counts = np.bincount(lab[ok], minlength=n)
    present = np.flatnonzero(counts > 0)
    # Ties in size broken by the lowest corner: invariant to point order and to translation.
    mins = np.full((n, 3), np.inf)
    for d in range(3):
        np.minimum.at(mins[:, d], lab[ok], cp[ok, d])
    order = present[
        np.lexsort((mins[present, 2], mins[present, 1], mins[present, 0], -counts[present]))
    ]
    new_id = np.full(n, -1, dtype=np.int64)
    new_id[order] = np.arange(len(order))
    out[ok] = new_id[lab[ok]]

    lookups = [_SupportLookup(s) for s in surfaces]
    sort_idx = np.argsort(out, kind="stable")
    bounds = np.searchsorted(out[sort_idx], np.arange(-1, len(order) + 1))
    clusters = []
    for cid in range(len(order)):  # one iteration per cluster
        p = cp[sort_idx[bounds[cid + 1] : bounds[cid + 2]]]
        clusters.append(_make_cluster(cid, p, lookups, params.support_tolerance))
    return clusters, out


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
        mask = ndimage.binary_fill_holes(mask)
        if dilate:
            mask = ndimage.binary_dilation(mask, structure=np.ones((3, 3), dtype=bool))
        self.mask = mask

    def over(self, xy: np.ndarray) -> np.ndarray:
        """(P,) bool: which x, y points (P, 2) lie over this surface's (filled) footprint."""
        ij = np.floor(xy / self.cell).astype(np.int64) - self.origin
        inside = (ij >= 0).all(axis=1) & (ij < np.array(self.mask.shape)).all(axis=1)
        res = np.zeros(len(xy), dtype=bool)
        res[inside] = self.mask[ij[inside, 0], ij[inside, 1]]
        return res


def _support(p: np.ndarray, lookups: list[_SupportLookup], tol: float) -> tuple[int | None, float]:
    """Surface id under the lowest points of cluster p (P, 3) and the bottom z used."""
    z = p[:, 2]
    # A robust bottom: one stray low point must not decide what the cluster stands on.
    bottom = float(np.percentile(z, 1.0)) if len(z) >= 100 else float(z.min())
    low = p[z <= bottom + _BOTTOM_BAND]
    best: tuple[float, float, int] | None = None
    for lk in lookups:  # one iteration per surface
        gap = bottom - lk.height
        # Surface points within point_tolerance were removed, so object bottoms start a little
        # above the surface; noise may put them a little below.
        if not -tol <= gap <= tol:
            continue
        frac = float(lk.over(low[:, :2]).mean())
        if frac < _SUPPORT_MIN_FRACTION:
            continue
        key = (frac, -abs(gap), -lk.id)
        if best is None or key > best:
            best = key
    return (None if best is None else -best[2]), bottom


def _make_cluster(cid: int, p: np.ndarray, lookups: list[_SupportLookup], tol: float) -> Cluster:
    """Properties of one cluster p (P, 3)."""
    sid, _ = _support(p, lookups, tol)
    lo, hi = p.min(axis=0), p.max(axis=0)
    base = lookups[[lk.id for lk in lookups].index(sid)].height if sid is not None else lo[2]

    xy = p[:, :2]
    footprint = _hull_2d(xy)
    # The hull, never the raw points: the edge search is quadratic in its vertices.
    centre_xy, length, width, yaw = _oriented_rect(footprint)

    return Cluster(
        id=cid,
        surface_id=sid,
        point_count=len(p),
        centroid=p.mean(axis=0),
        bbox_min=lo,
        bbox_max=hi,
        obb_center=np.array([centre_xy[0], centre_xy[1], (lo[2] + hi[2]) / 2]),
        obb_size=np.array([length, width, hi[2] - lo[2]]),
        obb_yaw=yaw,
        height=float(hi[2] - base),
        footprint=footprint,
        volume=_hull_volume(p),
    )


def _oriented_rect(xy: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """Yaw-only box around xy (K, 2): (centre (2,), length, width, yaw of the length axis).

    For a hull polygon, the minimum-area rectangle (one side is flush with a hull edge, so only
    the K edge directions are tried); PCA of the spread would be arbitrary for a square footprint
    and too wide for a cylinder next to a box. Degenerate sets use the principal axis.
    """
    if len(xy) >= 3:
        edges = np.roll(xy, -1, axis=0) - xy
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


def _hull_volume(p: np.ndarray) -> float:
    """Convex-hull volume of p (P, 3), m^3; 0 for fewer than 4 points or a flat set."""
    if len(p) < 4:
        return 0.0
    try:
        return float(ConvexHull(p).volume)
    except (QhullError, ValueError):
        return 0.0
