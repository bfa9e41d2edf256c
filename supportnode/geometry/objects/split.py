"""Splitting touching objects (the report's main error: barrels side by side merged).

A cluster whose x, y footprint falls apart into large parts under a morphological opening of
radius ``split_neck_width / 2`` is cut along the neck (`split_footprint`); one whose footprint
has no neck but whose top is two flat levels side by side, each standing on the surface (two
boxes of different heights face to face), is cut at the step (`split_step`); else, when
``split_concave``, along concave creases (`split_concave`). Clusters are never split
vertically: a box standing on another stays with it. Clusters wider than room structure
(convexity's ``_MAX_EXTENT``) are never split.

Points cp (M, 3) float64 metres, z up; labels (M,) int64, -1 = none.
"""

from __future__ import annotations

import functools

import numpy as np

from supportnode.geometry.memo import Memo
from supportnode.geometry.objects.arrays import _group_by_label
from supportnode.geometry.objects.convexity import _MAX_EXTENT
from supportnode.geometry.objects.split_concave import _CONCAVE_MAX_EXTENT, _split_concave
from supportnode.geometry.objects.split_footprint import _may_split, _split_recursive
from supportnode.geometry.objects.split_step import _STEP_MAX_EXTENT, _split_step
from supportnode.params import ObjectParams

# Footprint raster cell = voxel_size / this (1 cm at the default 3 cm voxels).
_SPLIT_CELL_DIVISOR = 3.0
# Recursion depth of splitting: up to 2**depth parts per cluster.
_SPLIT_DEPTH = 3


def _split_touching(
    cp: np.ndarray, lab: np.ndarray, params: ObjectParams, stats: dict, memo: Memo | None = None
) -> np.ndarray:
    """Cut clusters whose x, y footprint has large parts joined by a neck (see _split_footprint),
    or else whose top steps between two flat levels side by side (see _split_step). memo: the
    cuts of clusters seen with the same points in the previous detection."""
    cell = params.cluster_cell / _SPLIT_CELL_DIVISOR
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
    # Room structure (a ring of walls, a counter's run of cabinets) is no object to part: its
    # pieces would be no objects either, and under noise every wall is thick enough to be
    # tried (a room-sized raster, a third of a noisy map's objects stage). As the convex
    # method, it stays whole.
    room = (hi - lo).max(axis=1) > _MAX_EXTENT
    tried = np.flatnonzero(nonempty & _may_split(shape, cell, radius) & ~room)
    bottom = np.full(n + 1, -np.inf)  # the last: no cluster
    bottom[:n][nonempty] = np.minimum.reduceat(cp[order[bounds[1] :], 2], starts)[nonempty]
    point_bottom = bottom[lab]  # (M,) the lowest height of each point's cluster
    for c in tried:
        idx = order[bounds[c + 1] : bounds[c + 2]]
        extent = float((hi[c] - lo[c]).max())
        above = _standing_on(cp, point_bottom, idx, lo[c], hi[c], params.cluster_cell)
        if memo is None:
            parts, n_parts, how = _split_one(cp, idx, all_xy, extent, params, cell, radius, above)
        else:  # a pure function of the cluster's points and of what stands on it
            parts, n_parts, how = memo.get(
                "split",
                np.take(cp, np.concatenate([idx, above]), axis=0),
                functools.partial(_split_one, cp, idx, all_xy, extent, params, cell, radius, above),
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


def _standing_on(
    cp: np.ndarray,
    point_bottom: np.ndarray,
    idx: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    reach: float,
) -> np.ndarray:
    """(Q,) indices of the points of the other clusters standing on the cluster of points
    cp[idx]: those within its x, y box [lo, hi] (2,) of clusters whose lowest point
    (point_bottom (M,), metres, per point) lies above its median height (a box on a book, not
    a can beside it) and at most ``reach`` metres above its top (not what stands on the shelf
    board above)."""
    z = cp[idx, 2]
    pb = point_bottom
    cand = np.flatnonzero((pb >= np.median(z)) & (pb <= z.max() + reach))
    if len(cand) == 0:
        return cand
    x, y = cp[cand, 0], cp[cand, 1]
    return cand[(x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1])]


def _split_one(
    cp: np.ndarray,
    idx: np.ndarray,
    all_xy: np.ndarray,
    extent: float,
    params: ObjectParams,
    cell: float,
    radius: float,
    above: np.ndarray | None = None,
) -> tuple[np.ndarray, int, str | None]:
    """Parts (P,) of the cluster of points cp[idx] (x, y footprint extent in metres), their
    number, and the stats key of the rule that cut it ("step_splits", "concave_splits"; None
    for a neck or no cut). above: (Q,) indices of the points standing on it (their cells
    fill its footprint), or None."""
    xy_c = np.take(all_xy, idx, axis=0)
    fill = None if above is None or len(above) == 0 else np.take(all_xy, above, axis=0)
    parts = _split_recursive(xy_c, cell, radius, params.min_points, _SPLIT_DEPTH, fill)
    n_parts = int(parts.max()) + 1
    if n_parts >= 2 or extent > _STEP_MAX_EXTENT:
        return parts, n_parts, None
    p_c = np.take(cp, idx, axis=0)
    step, dense = _split_step(p_c, params.cluster_cell, params.min_points)
    if step is not None:
        return step, 2, "step_splits"
    if dense and params.split_concave and extent <= _CONCAVE_MAX_EXTENT:
        # Not tried on sparse footprints (far scans) or wide structure.
        conc = _split_concave(p_c, params.cluster_cell, params.concave_tolerance, params.min_points)
        if conc is not None:
            return conc, int(conc.max()) + 1, "concave_splits"
    return parts, n_parts, None
