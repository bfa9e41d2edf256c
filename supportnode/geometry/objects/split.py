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
from collections.abc import Callable

import numpy as np

from supportnode.geometry.memo import Memo
from supportnode.geometry.nearest import nearest
from supportnode.geometry.objects.convexity import _MAX_EXTENT
from supportnode.geometry.objects.layers import Groups
from supportnode.geometry.objects.split_concave import (
    _CONCAVE_MAX_EXTENT,
    _split_concave,
    _split_walls,
)
from supportnode.geometry.objects.split_footprint import Fill, _may_split, _split_recursive
from supportnode.geometry.objects.split_step import _STEP_MAX_EXTENT, _split_steps
from supportnode.kernels.groups import group_rows
from supportnode.params import ObjectParams

# Footprint raster cell = voxel_size / this (1 cm at the default 3 cm voxels).
_SPLIT_CELL_DIVISOR = 3.0
# A cluster is a flat thing when this share of its points lie within half a cell of its top.
_FLAT_TOP = 0.7
# Recursion depth of splitting: up to 2**depth parts per cluster.
_SPLIT_DEPTH = 3


def _split_touching(
    cp: np.ndarray,
    lab: np.ndarray,
    params: ObjectParams,
    stats: dict,
    memo: Memo | None = None,
    origin: np.ndarray | None = None,
    groups: Groups | None = None,
    level: np.ndarray | None = None,
    sparse: np.ndarray | None = None,
) -> np.ndarray:
    """Cut clusters whose x, y footprint has large parts joined by a neck (see _split_footprint),
    or else whose top steps between two flat levels side by side (see _split_step). memo: the
    cuts of clusters seen with the same points in the previous detection; origin: (3,) the
    sensor, metres, or None (what other clusters hide from it fills a footprint's notches);
    groups: ``group_rows(cp, lab, n)`` when the caller has it (layers.cut_layers); level:
    (M,) bool, the points at their surface's level (see level.py), left out of footprints;
    sparse: (M,) bool, the points of clusters too sparse for convexity (None: all), whose
    walls may seed parts (see split_concave._split_walls)."""
    cell = params.cluster_cell / _SPLIT_CELL_DIVISOR
    radius = params.split_neck_width / 2.0
    n = int(lab.max()) + 1
    out = lab.copy()
    if n == 0:
        return out
    # The clusters' rows (a stable counting sort) and boxes, to skip the clusters too narrow
    # to split without gathering their points (most clusters: wall strips, small objects).
    start, order, _, box_lo, box_hi = groups if groups is not None else group_rows(cp, lab, n)
    nonempty = start[1:] > start[:-1]
    box_lo[~nonempty] = 0.0
    box_hi[~nonempty] = 0.0
    lo, hi = box_lo[:, :2], box_hi[:, :2]
    # Contiguous (np.take on a strided view copies it first), column by column: copying the
    # (M, 2) view in one go runs numpy's inner loop over 2 elements, 6x slower.
    all_xy = np.empty((len(cp), 2))
    all_xy[:, 0] = cp[:, 0]
    all_xy[:, 1] = cp[:, 1]
    shape = np.floor((hi - lo) / cell).astype(np.int64) + 3  # as _split_footprint rasterises
    next_id = n
    # Room structure (a ring of walls, a counter's run of cabinets) is no object to part: its
    # pieces would be no objects either, and under noise every wall is thick enough to be
    # tried (a room-sized raster, a third of a noisy map's objects stage). As the convex
    # method, it stays whole.
    room = (hi - lo).max(axis=1) > _MAX_EXTENT
    tried = np.flatnonzero(nonempty & _may_split(shape, cell, radius) & ~room)
    bottom = np.full(n + 1, -np.inf)  # the last: no cluster
    bottom[:n][nonempty] = box_lo[nonempty, 2]
    point_bottom = bottom[lab]  # (M,) the lowest height of each point's cluster
    for c in tried:
        idx = order[start[c] : start[c + 1]]
        extent = float((hi[c] - lo[c]).max())
        fill = functools.partial(_fill_xy, cp, lab, idx, point_bottom, lo[c], hi[c], params, origin)
        at = None if level is None else level[idx]
        at = at if at is not None and at.any() and not at.all() else None
        walls = sparse is None or 2 * np.count_nonzero(sparse[idx]) > len(idx)
        split = functools.partial(_split_one, cp, idx, all_xy, extent, params, cell, radius)
        parts, n_parts, how = _split_remembered(split, all_xy, idx, fill, at, walls, memo)
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


def _split_remembered(
    split: Callable[..., tuple[np.ndarray, int, str | None]],
    all_xy: np.ndarray,
    idx: np.ndarray,
    fill: Callable[[], np.ndarray],
    at: np.ndarray | None,
    walls: bool,
    memo: Memo | None,
) -> tuple[np.ndarray, int, str | None]:
    """``split(fill, at, walls)`` (`_split_one` of the cluster of points idx), from the memo
    when it holds the same cluster: the cut is a pure function of the cluster's points
    all_xy[idx], of what fills its notches, of which are at the level and of ``walls``."""
    if memo is None:  # the fill is found only for a cluster with a neck
        return split(functools.cache(fill), at, walls)
    fill_xy = fill()
    key = [np.take(all_xy, idx, axis=0), fill_xy]
    if at is not None:  # which points are at the level: after a row of NaN
        key += [np.full((1, 2), np.nan), np.c_[np.flatnonzero(at), np.zeros(at.sum())]]
    if not walls:
        key.append(np.full((1, 2), np.inf))
    return memo.get("split", np.concatenate(key), functools.partial(split, fill_xy, at, walls))


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


def _fill_xy(
    cp: np.ndarray,
    lab: np.ndarray,
    idx: np.ndarray,
    point_bottom: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    params: ObjectParams,
    origin: np.ndarray | None,
) -> np.ndarray:
    """(Q, 2) x, y, metres, that fill the notches of the footprint of cluster cp[idx] (box
    [lo, hi] (2,)): what stands on it (see _standing_on) and, with the sensor at origin (3,),
    the points of the other clusters higher than its top seen along their rays down to its
    top's height (what they hide of it: a small box's shadow across a book)."""
    above = _standing_on(cp, point_bottom, idx, lo, hi, params.cluster_cell)
    fill = np.take(cp[:, :2], above, axis=0)
    z = cp[idx, 2]
    z_top = float(np.max(z))
    if origin is None or not origin[2] > z_top:
        return fill
    # A band hidden across a flat thing's top (a book: most of what is seen of it is its top)
    # continues that plane; between two things behind an occluder it tells nothing.
    if np.mean(z >= np.percentile(z, 95) - params.cluster_cell / 2) < _FLAT_TOP:
        return fill
    # Only what lies between the sensor and the box, in x, y, can hide part of it.
    near = np.minimum(lo, origin[:2]), np.maximum(hi, origin[:2])
    x, y = cp[:, 0], cp[:, 1]
    high = np.flatnonzero(
        (cp[:, 2] > z_top)
        & (x >= near[0][0])
        & (x <= near[1][0])
        & (y >= near[0][1])
        & (y <= near[1][1])
        & (lab >= 0)
        & (lab != lab[idx[0]])
    )
    q = np.take(cp, high, axis=0)
    t = (origin[2] - z_top) / (origin[2] - q[:, 2])  # along the ray from the sensor, >= 1
    shadow = origin[:2] + t[:, None] * (q[:, :2] - origin[:2])
    sx, sy = shadow[:, 0], shadow[:, 1]
    inside = (sx >= lo[0]) & (sx <= hi[0]) & (sy >= lo[1]) & (sy <= hi[1])
    return np.concatenate([fill, shadow[inside]])


def _split_one(
    cp: np.ndarray,
    idx: np.ndarray,
    all_xy: np.ndarray,
    extent: float,
    params: ObjectParams,
    cell: float,
    radius: float,
    fill: Fill = None,
    level: np.ndarray | None = None,
    walls: bool = True,
) -> tuple[np.ndarray, int, str | None]:
    """Parts (P,) of the cluster of points cp[idx] (x, y footprint extent in metres), their
    number, and the stats key of the rule that cut it ("step_splits", "concave_splits"; None
    for a neck or no cut). fill: what fills its footprint's notches (see _fill_xy and
    split_footprint.Fill). level: (P,) bool, its points at the surface's level: left out of
    the footprint (the table's skirt would fill its necks) and the step rule (it would be a
    flat level of its own), each in the part of its nearest other point in x, y. walls: a
    sparse cluster, which may be cut where its walls part at concave creases (a dense one was
    segmented by convexity at a finer cell)."""
    xy_c = np.take(all_xy, idx, axis=0)
    own = np.arange(len(idx)) if level is None else np.flatnonzero(~level)
    xy_own = xy_c if level is None else np.take(xy_c, own, axis=0)
    parts = _split_recursive(xy_own, cell, radius, params.min_points, _SPLIT_DEPTH, fill)
    n_parts = int(parts.max()) + 1
    if n_parts >= 2 or extent > _STEP_MAX_EXTENT:
        return _with_level(parts, level, xy_c), n_parts, None
    p_c = np.take(cp, idx, axis=0)
    step, dense = _split_steps(
        p_c if level is None else p_c[own], params.cluster_cell, params.min_points
    )
    if step is not None:
        return _with_level(step, level, xy_c), int(step.max()) + 1, "step_splits"
    if dense and params.split_concave and extent <= _CONCAVE_MAX_EXTENT:
        # Not tried on sparse footprints (far scans) or wide structure. With the level points:
        # the crease rule was built on them (its parts stand on the cluster's bottom).
        conc = _split_concave(p_c, params.cluster_cell, params.concave_tolerance, params.min_points)
        if conc is not None:
            return conc, int(conc.max()) + 1, "concave_splits"
    if walls and dense and extent <= _CONCAVE_MAX_EXTENT:
        seeded = _split_walls(
            p_c if level is None else p_c[own],
            params.cluster_cell,
            params.concave_tolerance,
            params.min_points,
        )
        if seeded is not None:
            return _with_level(seeded, level, xy_c), int(seeded.max()) + 1, "wall_splits"
    return _with_level(parts, level, xy_c), n_parts, None


def _with_level(parts: np.ndarray, level: np.ndarray | None, xy: np.ndarray) -> np.ndarray:
    """(P,) parts of all the cluster's points xy (P, 2) from ``parts`` of those not at the
    level (level: (P,) bool or None): each level point in the part of its nearest other
    point in x, y."""
    if level is None:
        return parts
    out = np.zeros(len(xy), np.int64)
    own = ~level
    out[own] = parts
    if parts.max() > 0:
        out[level] = parts[nearest(xy[own], xy[level])]
    return out


def _nearest(xy: np.ndarray, query: np.ndarray) -> np.ndarray:
    """(Q,) row of the point of xy (P, 2) nearest each of query (Q, 2)."""
    return nearest(xy, query)
