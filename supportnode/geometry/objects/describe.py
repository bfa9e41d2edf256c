"""Describing segmented objects: a Cluster (centroid, boxes, footprint hull, volume, height
above its surface) per cluster of a Segmentation, and which cluster stands on which.

Lengths in metres, z up; see `hull` for the footprint and box geometry and `support` for
supported_by.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np

from supportnode.geometry.memo import Memo
from supportnode.geometry.objects.hull import _oriented_rects, _volume
from supportnode.geometry.objects.result import Cluster, Segmentation
from supportnode.geometry.objects.support import supported_by
from supportnode.kernels.groups import run_sums
from supportnode.kernels.hull import footprint_hulls


def _describe(seg: Segmentation, memo: Memo | None = None, volumes: bool = True) -> list[Cluster]:
    """Footprints (exact x, y convex hulls), oriented boxes and heights of the clusters of
    seg, in its order; volumes False: no convex-hull volumes (NaN, no 3-D hulls taken)."""
    if len(seg.surface_ids) == 0:
        return []
    runs = seg._runs.tolist()
    groups = [seg._grouped[a:b] for a, b in runs]  # one slice per cluster
    # Each cluster's coordinates summed in point order (as p.mean(axis=0) does), in one pass.
    sums = run_sums(seg._grouped, seg._runs[:, 0], seg._runs[:, 1])
    lo, hi = seg.bbox_min, seg.bbox_max  # bounding boxes: the same min / max as per cluster
    rows_of, ring = footprint_hulls(seg._grouped, seg._runs[:, 0], seg._runs[:, 1])
    corners = seg._grouped[rows_of, :2]  # every ring's vertices, gathered once
    footprints = [corners[a:b] for a, b in _pairs(ring)]
    if not volumes:
        volume = [float("nan")] * len(groups)
    elif memo is None:
        volume = [_volume(p, lo[cid], hi[cid]) for cid, p in enumerate(groups)]
    else:  # lo, hi are p's own bounds: a pure function of p
        volume = [
            memo.get("volume", p, functools.partial(_volume, p, lo[cid], hi[cid]))
            for cid, p in enumerate(groups)
        ]  # per cluster
    hulls = list(zip(footprints, volume, strict=True))
    # The hulls, never the raw points: the edge search is quadratic in the vertices.
    rects = _oriented_rects(footprints)
    return [
        _make_cluster(
            cid,
            sums[cid] / (runs[cid][1] - runs[cid][0]),
            runs[cid][1] - runs[cid][0],
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


def _pairs(starts: np.ndarray) -> list[tuple[int, int]]:
    """(start, end) of each run of starts (C + 1,)."""
    return list(itertools.pairwise(starts.tolist()))


def _make_cluster(
    cid: int,
    centroid: np.ndarray,
    n: int,
    lo: np.ndarray,
    hi: np.ndarray,
    sid: int | None,
    height_of: dict[int, float],
    hull: tuple[np.ndarray, float],
    rect: tuple[np.ndarray, float, float, float],
) -> Cluster:
    """Properties of one cluster of n points standing on surface sid (heights by surface id).

    centroid: (3,) the mean of its points; lo, hi: (3,) their bounding box; hull: footprint
    (K, 2) and volume (m^3, NaN: not taken); rect: oriented box of the footprint (see
    _oriented_rect).
    """
    base = height_of[sid] if sid is not None else lo[2]
    footprint, volume = hull
    centre_xy, length, width, yaw = rect
    return Cluster(
        id=cid,
        surface_id=sid,
        point_count=n,
        centroid=centroid,
        bbox_min=lo,
        bbox_max=hi,
        obb_center=np.array([centre_xy[0], centre_xy[1], (lo[2] + hi[2]) / 2]),
        obb_size=np.array([length, width, hi[2] - lo[2]]),
        obb_yaw=yaw,
        height=float(hi[2] - base),
        footprint=footprint,
        volume=volume,
    )


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
