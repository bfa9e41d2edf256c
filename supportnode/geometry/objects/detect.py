"""Supported objects: clusters of the points that lie on no support surface.

The public entry points, in stages: :func:`cluster_objects` (connected components of the
candidates, by the ``knn``, ``voxel`` or ``convex`` method, see `clusters` and `convexity`),
:func:`split_objects` (touching objects split, see `split`; clusters ordered largest first,
each attached to the surface directly under its lowest points, see `support_lookup`) and
:func:`describe_objects` (hulls, boxes, heights, see `describe`). :func:`segment_objects` is
the first two, :func:`detect_objects` all three.

Points (N, 3) float metres, z up; labels (N,) int32, -1 for surface points, noise and
unlabelled points.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from supportnode.errors import InputError
from supportnode.geometry.memo import Memo
from supportnode.geometry.objects.attached import join_attached
from supportnode.geometry.objects.clusters import (
    _cluster_knn,
    _cluster_voxel,
    _drop_small,
    _order,
)
from supportnode.geometry.objects.convexity import CELL_STEPS, cell_levels, cluster_convex
from supportnode.geometry.objects.describe import _describe, _stack
from supportnode.geometry.objects.feet import claim_feet, claim_raised
from supportnode.geometry.objects.layers import cut_layers
from supportnode.geometry.objects.level import extend_lookups, nearest_bottom, set_aside
from supportnode.geometry.objects.result import Components, ObjectResult, Segmentation
from supportnode.geometry.objects.split import _split_touching
from supportnode.geometry.objects.support_lookup import _lookups, _support_below
from supportnode.geometry.surfaces import SurfaceResult
from supportnode.params import ObjectParams

__all__ = [
    "cluster_objects",
    "convex_components",
    "describe_objects",
    "detect_objects",
    "segment_objects",
    "split_objects",
]


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
    if params.method == "convex" and not any(s.band[0] > 0 for s in surfaces.surfaces):
        # Groups by voxels first (their level points set aside, see level), segmented by
        # convexity where they are dense enough: as the pipeline runs it, free space between.
        voxel = dataclasses.replace(params, method="voxel")
        groups = _components(points, surfaces, voxel, sensor_origin)
        return convex_components(groups, points, surfaces, params, sensor_origin)
    return _components(points, surfaces, params, sensor_origin)


def _components(
    points: np.ndarray,
    surfaces: SurfaceResult,
    params: ObjectParams,
    sensor_origin: np.ndarray | None = None,
) -> Components:
    """:func:`cluster_objects` by ``params.method`` alone."""
    pts, surf_labels = _checked(points, surfaces)
    t0 = time.perf_counter()
    cand = np.flatnonzero(surf_labels == -1)
    cp = np.take(pts, cand, axis=0)  # np.take: 5x faster than pts[cand] for (N, 3) rows
    stats: dict = {"method": params.method, "candidates": len(cand)}
    lookups = _lookups(surfaces.surfaces)
    if params.method == "voxel":  # the footprints' rings run on along their level
        lookups = extend_lookups(cp, lookups, surfaces.surfaces)
    level = bottom = np.zeros(0, np.int64)
    if params.method in ("voxel", "convex"):
        support = _support_below(cp, surfaces.surfaces, params.support_tolerance, lookups)
    if params.method == "voxel":
        # Grouped and split without the points at their surface's level, given back after
        # (see level). Not by convexity: the crease at an object's foot parts it from them.
        cand, cp, support, bottom, level = set_aside(
            cand, cp, support, surfaces.surfaces, params.cluster_cell
        )
    stats["level_points"] = len(level)
    if params.method == "knn":
        lab = _cluster_knn(cp, params, stats)
    elif params.method == "voxel":
        lab = _cluster_voxel(cp, params.cluster_cell, stats, support)
    elif params.method == "convex":
        lab = cluster_convex(cp, surfaces.surfaces, support, params, sensor_origin, stats)
    else:
        raise InputError(
            f"unknown object method {params.method!r}; expected 'knn', 'voxel' or 'convex'"
        )
    voxels = stats.pop("_voxel_of_point", None)
    sparse = stats.pop("_sparse_point", None)
    level_xyz = np.take(pts, level, axis=0)
    near = nearest_bottom(level_xyz, cp, lab, bottom, params.cluster_cell)
    lab = _drop_small(lab, params.min_points, lab[near[near >= 0]])  # the level points count
    if params.method != "knn":
        heights = {s.id: s.height for s in surfaces.surfaces}
        lab = join_attached(cp, lab, support, heights)
    claimed = np.zeros(0, np.int64)
    if params.foot_reach > 0 and any(s.band[0] > 0 for s in surfaces.surfaces) and len(lab):
        if params.method == "knn":
            support = _support_below(cp, surfaces.surfaces, params.support_tolerance, lookups)
        cand, cp, lab, claimed = _claim_feet(pts, surfaces, cand, cp, lab, support, params)
        stats["foot_points"] = len(claimed)
        if sparse is not None:  # the feet belong to dense (segmented) objects
            sparse = np.r_[sparse, np.zeros(len(cp) - len(sparse), bool)]
    if len(level):  # last, after the feet: each with its nearest object point's label
        given = np.full(len(near), -1, np.int64)
        given[near >= 0] = lab[near[near >= 0]]
        cand, cp = np.concatenate([cand, level]), np.concatenate([cp, level_xyz])
        lab = np.concatenate([lab, given])
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
    if params.method != "voxel" or len(claimed):
        voxels = None
    origin = None if sensor_origin is None else np.asarray(sensor_origin, np.float64)
    return Components(
        seg, cp, cand, lab, sids, lookups, len(pts), stats, claimed, voxels, origin, sparse, near
    )


def _checked(points: np.ndarray, surfaces: SurfaceResult) -> tuple[np.ndarray, np.ndarray]:
    """The (N, 3) float64 points and their (N,) surface labels, or InputError."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {pts.shape}")
    surf_labels = np.asarray(surfaces.labels)
    if surf_labels.shape != (len(pts),):
        raise InputError(f"surface labels have shape {surf_labels.shape}, expected ({len(pts)},)")
    if not np.isfinite(pts).all():
        raise InputError("points contain NaN or infinite values")
    return pts, surf_labels


def convex_components(
    components: Components,
    points: np.ndarray,
    surfaces: SurfaceResult,
    params: ObjectParams,
    sensor_origin: np.ndarray | None = None,
) -> Components:
    """The ``convex`` method's components of the points, given ``components``, the same
    points' components by the ``voxel`` method (:func:`cluster_objects`, same arguments):
    those, when none of them is dense enough to be segmented by convexity (a lidar's or a
    map's points: the convex method keeps them as they are), else the points segmented by
    convexity (``params``, method ``convex``)."""
    vox = components._voxels
    if vox is None:
        return _components(points, surfaces, params, sensor_origin)
    m = len(components._points) - len(components._level_near)  # the voxels' points
    level = cell_levels(components._points[:m], components._labels[:m], vox, params)
    if (level < len(CELL_STEPS)).any():
        return _components(points, surfaces, params, sensor_origin)
    stats = dict(components._stats, method="convex", dense_components=0)
    sparse = np.ones(len(components._points), bool)
    return dataclasses.replace(components, _stats=stats, _sparse=sparse)


# The band points searched for feet lie within this of the objects' x, y box, metres.
_AROUND = 0.05


def _claim_feet(
    pts: np.ndarray,
    surfaces: SurfaceResult,
    cand: np.ndarray,
    cp: np.ndarray,
    lab: np.ndarray,
    support: np.ndarray,
    params: ObjectParams,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The objects' feet (see `feet.claim_feet`) added to the candidates: the surface points
    under an object and the unclaimed candidates over a surface there. Returns the
    candidates' rows, points and labels with the feet, and the surface rows taken."""
    height = np.full(max(s.id for s in surfaces.surfaces) + 1, np.nan)
    for s in surfaces.surfaces:
        height[s.id] = s.height
    # Only over surfaces whose noise band labelled them (a depth camera's): elsewhere the
    # surface's own tolerance and k-NN normals already decided (see surfaces.band).
    by_band = np.zeros(len(height), dtype=bool)
    for s in surfaces.surfaces:
        by_band[s.id] = s.band[0] > 0
    is_raised = np.zeros(len(pts), dtype=bool)
    is_raised[surfaces.raised] = True
    # Only the band around the objects matters (and the raised patches, wherever they lie).
    lo, hi = np.full(2, -np.inf), np.full(2, np.inf)
    obj = lab >= 0
    if obj.any():
        for a in range(2):  # column by column: (M, 2) reductions are several times slower
            col = cp[:, a][obj]
            lo[a], hi[a] = col.min() - _AROUND, col.max() + _AROUND
    # Imported here: only band-labelled surfaces (a depth camera's) get here, and
    # `runtime.warm` loads the kernels of every imported kernel module (~4 ms each).
    from supportnode.kernels.band import band_rows

    on = band_rows(pts, surfaces.labels, by_band, lo, hi, is_raised)
    loose = np.flatnonzero((lab < 0) & (support >= 0))
    loose = loose[by_band[support[loose]]]
    band_xyz = np.concatenate([np.take(pts, on, axis=0), np.take(cp, loose, axis=0)])
    band_surf = np.concatenate([surfaces.labels[on].astype(np.int64), support[loose]])
    cell = params.convex_cell
    owner = claim_feet(
        band_xyz, band_surf, height, cp, lab, support, height, cell, params.foot_reach
    )
    raised = np.r_[is_raised[on], is_raised[cand[loose]]]
    owner = claim_raised(
        band_xyz, owner, raised, cp, lab, 2 * cell, 3 * params.foot_reach, params.min_points
    )
    took = owner[: len(on)] >= 0
    lab = lab.copy()
    lab[loose] = np.where(owner[len(on) :] >= 0, owner[len(on) :], lab[loose])
    rows = on[took]
    cand = np.concatenate([cand, rows])
    cp = np.concatenate([cp, np.take(pts, rows, axis=0)])
    lab = np.concatenate([lab, owner[: len(on)][took]])
    return cand, cp, lab, rows


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
    stats["wall_splits"] = 0  # of which cut where their walls part (sparse clusters)
    stats["layer_splits"] = 0  # sparse clusters cut where one stands on another's top
    known = components._supports
    split = lab
    near = components._level_near
    m = len(cp) - len(near)  # the last rows: points at a surface's level (see level)
    if params.split_touching and len(lab):
        groups = None
        if components._sparse is not None:  # with the level points: bottoms measured on them
            split, groups = cut_layers(
                cp, split, components._sparse, known, params, stats, components.segmentation._groups
            )
        level = None
        if len(near):  # footprints without them (see level)
            level = np.zeros(len(cp), bool)
            level[m:] = True
        split = _split_touching(
            cp, split, params, stats, memo, components._origin, groups, level, components._sparse
        )
    t2 = time.perf_counter()
    if stats["merged_splits"] == 0 and stats["layer_splits"] == 0:
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


def describe_objects(
    seg: Segmentation, memo: Memo | None = None, volumes: bool = True
) -> ObjectResult:
    """The second half of :func:`detect_objects`: the clusters of ``seg`` described (hulls,
    oriented boxes, heights). memo: as for detect_objects. volumes False: each cluster's
    volume is NaN, its 3-D convex hull not taken (the same footprints, in a third of the
    time)."""
    t = time.perf_counter()
    clusters = _describe(seg, memo, volumes)
    _stack(clusters, seg._heights)
    stats = dict(seg.stats)
    stats["time_describe_s"] = time.perf_counter() - t + stats.pop("time_order_s", 0.0)
    return ObjectResult(clusters=clusters, labels=seg.labels, stats=stats)
