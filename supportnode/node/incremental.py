"""Detection on the node's map: a full recompute, or only the region a scan touched.

`regional` runs `pipeline.detect` on a crop of the map around what the scan changed and merges
the result with the previous detection's items that lie entirely outside. It returns None
(the caller then recomputes everything) whenever it cannot vouch that the merge equals a full
recompute:

- the region is closed over the previous items: any surface or cluster whose x, y box comes
  within ``margin`` of it joins it, repeatedly, so every item the change may affect is redone
  as a whole (a floor spanning the map makes the region the whole map: then the crop would
  save nothing and None is returned);
- the crop adds a context band of ``margin`` around the region; a new item that reaches into
  that band may be cut by the crop, so the result is refused;
- ``margin`` exceeds the reach of every local rule of the detection (voxel neighbourhoods,
  gap bridging, clutter absorption, k-NN normals, object support), 0.5 m by default.

Everything here is in the node's detection frame (map frame rotated to gravity). Pure.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from supportnode.geometry.freespace import FreeSpace
from supportnode.geometry.objects import Cluster
from supportnode.geometry.surfaces import Surface, detect_surfaces
from supportnode.kernels.crop import crop_rows
from supportnode.kernels.groups import rows_at_ranks
from supportnode.params import DetectParams
from supportnode.pipeline import objects_stage, surfaces_stage

__all__ = [
    "Items",
    "Phase",
    "begin_full",
    "begin_regional",
    "begin_regional_from",
    "full",
    "regional",
    "regional_from",
]

# A crop holding at least this share of the map's points is not worth the bookkeeping.
_MAX_CROP_SHARE = 0.8
# Points of each cluster kept for the ObstacleClusters message.
MAX_CLUSTER_POINTS = 64


@dataclass
class Items:
    """One detection with consecutive ids: surface i has id i, cluster j id j; clusters'
    ``surface_id`` and free spaces' ``surface_id`` refer to those ids."""

    surfaces: list[Surface] = field(default_factory=list)
    clusters: list[Cluster] = field(default_factory=list)
    free: list[FreeSpace] = field(default_factory=list)
    cluster_points: list[np.ndarray] = field(default_factory=list)  # (M, 3) float32 each
    timings: dict[str, float] = field(default_factory=dict)
    region: tuple[np.ndarray, np.ndarray] | None = None  # x, y box recomputed; None: all

    def has_free_space_below(self, height: float | None) -> bool:
        """Does every surface lower than ``height`` (m; None: every surface) have its free
        space in ``free``? (A detection with ``free_below`` leaves the higher ones out.)"""
        have = {f.surface_id for f in self.free}
        return all(s.id in have for s in self.surfaces if height is None or s.height < height)


def _box(item: Surface | Cluster) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(item.bbox_min[:2], float), np.asarray(item.bbox_max[:2], float)


def _meets(lo: np.ndarray, hi: np.ndarray, blo: np.ndarray, bhi: np.ndarray, m: float) -> bool:
    """Do the x, y boxes [lo, hi] grown by m and [blo, bhi] intersect?"""
    return bool(np.all(blo <= hi + m) and np.all(bhi >= lo - m))


@dataclass
class Phase:
    """A detection's first phase: ``surfaces`` (ids 0, 1, ... as in `Items`) and their
    ``free`` space are final; `finish` computes the objects and returns the whole `Items`
    (whose surfaces and free space are these). Two calls, so that a node can publish the
    surfaces before the objects are split and described; no threads."""

    surfaces: list[Surface]
    free: list[FreeSpace]
    _finish: Callable[[], Items] = field(repr=False)

    def finish(self) -> Items:
        """The objects, and with them the whole detection (call once)."""
        return self._finish()

    @staticmethod
    def done(items: Items) -> Phase:
        """The phase of a detection already complete (a reused one)."""
        return Phase(items.surfaces, items.free, lambda: items)


def _cluster_points(points: np.ndarray, labels: np.ndarray, n: int) -> list[np.ndarray]:
    """Up to MAX_CLUSTER_POINTS evenly spaced points of each cluster, in row order: those at
    ranks ``np.linspace(0, count - 1, MAX_CLUSTER_POINTS).round()`` of its rows (all of a
    smaller one), picked in one pass over the labels (see `kernels.groups`)."""
    if n == 0:
        return []
    counts = np.bincount(labels.astype(np.int64) + 1, minlength=n + 1)[1 : n + 1]
    keep = np.minimum(counts, MAX_CLUSTER_POINTS)
    j = np.arange(MAX_CLUSTER_POINTS)
    # np.linspace's arithmetic, row by row: j * step, the last one the end itself.
    spread = j[None, :] * ((counts - 1) / (MAX_CLUSTER_POINTS - 1))[:, None]
    spread[:, -1] = counts - 1
    ranks = np.where(counts[:, None] > MAX_CLUSTER_POINTS, spread.round(), j[None, :])
    starts = np.concatenate([[0], np.cumsum(keep)])
    rows = rows_at_ranks(labels, ranks[j[None, :] < keep[:, None]].astype(np.int64), starts)
    picked = np.take(points, rows, axis=0).astype(np.float32)
    return [picked[a:b] for a, b in itertools.pairwise(starts.tolist())]


def begin_full(
    points: np.ndarray,
    params: DetectParams,
    origin: np.ndarray | None = None,
    free_below: float | None = None,
) -> Phase:
    """`full`'s first phase: surfaces, components, free space (`pipeline.surfaces_stage`)."""
    pts = np.asarray(points, dtype=np.float64)
    timings: dict[str, float] = {}
    t = time.perf_counter()
    sr = detect_surfaces(pts, params.surfaces, sensor_origin=origin)
    timings["surfaces"] = time.perf_counter() - t
    early = surfaces_stage(pts, sr, params, free_below, timings, sensor_origin=origin)

    def finish() -> Items:
        # The node's messages carry no volume: no 3-D hulls (a fifth of the objects' time).
        objects = objects_stage(early, params, volumes=False)
        return Items(
            surfaces=list(sr.surfaces),
            clusters=list(objects.clusters),
            free=list(early.free),
            cluster_points=_cluster_points(pts, objects.labels, len(objects.clusters)),
            timings=timings,
        )

    return Phase(list(sr.surfaces), list(early.free), finish)


def full(
    points: np.ndarray,
    params: DetectParams,
    origin: np.ndarray | None = None,
    free_below: float | None = None,
) -> Items:
    """Detection on all of ``points`` (N, 3), metres, z up. free_below: free space only for
    surfaces lower than this, metres (None: all; see `pipeline.detect`)."""
    return begin_full(points, params, origin, free_below).finish()


def regional(
    points: np.ndarray,
    previous: Items,
    lo: np.ndarray,
    hi: np.ndarray,
    params: DetectParams,
    origin: np.ndarray | None = None,
    margin: float = 0.5,
    free_below: float | None = None,
) -> Items | None:
    """Detection equal to ``full(points, free_below=free_below)`` when only the x, y box
    [lo, hi] (2,) changed since ``previous`` was computed on the map; None when that cannot
    be guaranteed cheaply."""
    phase = begin_regional(points, previous, lo, hi, params, origin, margin, free_below)
    return None if phase is None else phase.finish()


def begin_regional(
    points: np.ndarray,
    previous: Items,
    lo: np.ndarray,
    hi: np.ndarray,
    params: DetectParams,
    origin: np.ndarray | None = None,
    margin: float = 0.5,
    free_below: float | None = None,
) -> Phase | None:
    """`regional`'s first phase (surfaces and free space; `Phase.finish` the rest)."""

    def fetch(blo: np.ndarray, bhi: np.ndarray, max_share: float) -> np.ndarray | None:
        # Given up as soon as the crop reaches max_share of the map (a moving sensor's
        # scan changes most of it): one compiled pass, not a mask over all points.
        share = max_share * len(points)
        limit = int(np.ceil(share)) if share <= len(points) else len(points) + 1
        rows = crop_rows(points, blo, bhi, limit)
        return None if rows is None else np.take(points, rows, axis=0)

    return begin_regional_from(fetch, previous, lo, hi, params, origin, margin, free_below)


def regional_from(
    fetch: Callable[[np.ndarray, np.ndarray, float], np.ndarray | None],
    previous: Items,
    lo: np.ndarray,
    hi: np.ndarray,
    params: DetectParams,
    origin: np.ndarray | None = None,
    margin: float = 0.5,
    free_below: float | None = None,
) -> Items | None:
    """`regional` on a map that hands out crops: ``fetch(box_lo, box_hi, max_share)`` returns
    the (P, 3) detection-frame points whose x, y lie in the box, or None when they would be at
    least ``max_share`` of the map (then a full recompute is cheaper). The node fetches from
    its voxel map, so the cost of a scan does not grow with the parts of the map it did not
    touch."""
    phase = begin_regional_from(fetch, previous, lo, hi, params, origin, margin, free_below)
    return None if phase is None else phase.finish()


def _inside(boxes: list, lo: np.ndarray, hi: np.ndarray, margin: float) -> tuple:
    """The region closed over the items' boxes: (inside mask, lo, hi). The closure is the
    smallest box holding the region and every box that meets it grown by ``margin``: unique,
    so each round takes every box that meets the region at once."""
    n = len(boxes)
    inside = np.zeros(n, bool)
    if n == 0:
        return inside, lo, hi
    blo = np.array([b[0] for b in boxes], float).reshape(n, 2)
    bhi = np.array([b[1] for b in boxes], float).reshape(n, 2)
    while True:  # closure: a few rounds
        meets = ~inside & (blo <= hi + margin).all(axis=1) & (bhi >= lo - margin).all(axis=1)
        if not meets.any():
            return inside, lo, hi
        inside |= meets
        lo = np.minimum(lo, blo[meets].min(axis=0))
        hi = np.maximum(hi, bhi[meets].max(axis=0))


def _kept(items: list, lo: np.ndarray, hi: np.ndarray, margin: float) -> list[int] | None:
    """Indices of the new items that meet the region; None when one of them reaches beyond
    region + margin (the crop may have cut it)."""
    keep = []
    for j, item in enumerate(items):
        blo, bhi = _box(item)
        if not _meets(lo, hi, blo, bhi, margin):
            continue  # entirely in the context band: a piece of an unchanged item
        if np.any(blo < lo - margin) or np.any(bhi > hi + margin):
            return None
        keep.append(j)
    return keep


def begin_regional_from(
    fetch: Callable[[np.ndarray, np.ndarray, float], np.ndarray | None],
    previous: Items,
    lo: np.ndarray,
    hi: np.ndarray,
    params: DetectParams,
    origin: np.ndarray | None = None,
    margin: float = 0.5,
    free_below: float | None = None,
) -> Phase | None:
    """`regional_from`'s first phase: None when the surfaces cannot be vouched for. Its
    `Phase.finish` checks the objects the same way; when those cannot be vouched for (a new
    cluster cut by the crop, or on a surface left out) the objects come from a full
    recompute, their surfaces matched to this phase's: the surfaces may have gone out."""
    if not previous.has_free_space_below(free_below):
        return None  # unchanged surfaces that now need their free space lack it
    lo, hi = np.asarray(lo, float).copy(), np.asarray(hi, float).copy()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(lo > hi):
        return None
    boxes = [_box(s) for s in previous.surfaces] + [_box(c) for c in previous.clusters]
    inside, lo, hi = _inside(boxes, lo, hi, margin)
    crop = fetch(lo - 2 * margin, hi + 2 * margin, _MAX_CROP_SHARE)
    if crop is None:
        return None
    new = begin_full(crop, params, origin, free_below=free_below)
    keep = _kept(new.surfaces, lo, hi, margin)
    if keep is None:
        return None
    keep_s = [new.surfaces[j] for j in keep]
    n_prev_s = len(previous.surfaces)
    old_s = [s for i, s in enumerate(previous.surfaces) if not inside[i]]
    sid_old = {s.id: k for k, s in enumerate(old_s)}
    sid_new = {s.id: len(old_s) + k for k, s in enumerate(keep_s)}
    surfaces = [dataclasses.replace(s, id=k) for k, s in enumerate(old_s + keep_s)]
    free = _renumbered(previous.free, sid_old) + _renumbered(new.free, sid_new)

    def finish() -> Items:
        done = new.finish()
        out = Items(surfaces, [], free, [], timings=done.timings, region=(lo, hi))
        keep_c = _kept(done.clusters, lo, hi, margin)
        if keep_c is None:
            return _objects_of_full(fetch, surfaces, free, params, origin, free_below)
        old_c = [j for j in range(len(previous.clusters)) if not inside[n_prev_s + j]]
        for src, idx, sid in ((previous, old_c, sid_old), (done, keep_c, sid_new)):
            for j in idx:
                c = src.clusters[j]
                if c.surface_id is not None and c.surface_id not in sid:
                    return _objects_of_full(fetch, surfaces, free, params, origin, free_below)
                s = None if c.surface_id is None else sid[c.surface_id]
                out.clusters.append(dataclasses.replace(c, id=len(out.clusters), surface_id=s))
                out.cluster_points.append(src.cluster_points[j])
        return out

    return Phase(surfaces, free, finish)


def _renumbered(free: list[FreeSpace], sid: dict[int, int]) -> list[FreeSpace]:
    """The free space of the surfaces kept, by the surfaces' new ids (sid: old id -> new)."""
    return [
        dataclasses.replace(f, surface_id=sid[f.surface_id]) for f in free if f.surface_id in sid
    ]


def _objects_of_full(
    fetch: Callable[[np.ndarray, np.ndarray, float], np.ndarray | None],
    surfaces: list[Surface],
    free: list[FreeSpace],
    params: DetectParams,
    origin: np.ndarray | None,
    free_below: float | None,
) -> Items:
    """The clusters of a full recompute, their surface ids those of the equal ``surfaces``
    (a full recompute finds the same surfaces, listed in another order)."""
    everything = fetch(np.full(2, -np.inf), np.full(2, np.inf), np.inf)
    assert everything is not None  # no share reaches infinity
    whole = full(everything, params, origin, free_below)

    def key(s: Surface) -> np.ndarray:
        return np.array([s.height, *s.bbox_min, *s.bbox_max], float)

    ours = [key(s) for s in surfaces]
    to_ours: dict[int, int] = {}
    for s in whole.surfaces:
        match = [k for k, o in enumerate(ours) if np.allclose(o, key(s), atol=1e-9)]
        if match:
            to_ours[s.id] = match[0]
    clusters = [
        dataclasses.replace(c, surface_id=to_ours.get(c.surface_id))
        if c.surface_id is not None
        else c
        for c in whole.clusters
    ]
    return Items(surfaces, clusters, free, whole.cluster_points, timings=whole.timings)
