"""Clustering the candidate points (those on no surface) into connected components, and
ordering the clusters.

- ``knn``: Algorithm 2 of the report as published. Sample a fraction ``s`` of the candidates, link
  two samples when either is among the other's ``k`` nearest neighbours, take connected components;
  every candidate then takes the label of its nearest sample within ``label_radius``.
- ``voxel`` (default, the report's own suggestion): 26-connected components of the occupied voxels
  of a fine grid. No sampling, so no seed and no lost thin parts; linear in the number of points.

(The ``convex`` method lives in `convexity`.) Components below ``min_points`` are dropped
(_drop_small); _order sorts clusters largest first and finds the surface each stands on.
Inputs cp (M, 3) float64 metres, z up; labels (M,) int64, -1 = none.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.neighbours import FORWARD_26
from supportnode.geometry.objects.result import Segmentation
from supportnode.geometry.objects.support_lookup import _SupportLookup, _supports
from supportnode.kernels.components import label_edges, label_voxel_grid
from supportnode.kernels.groups import group_rows
from supportnode.kernels.occupancy import grid_keys, occupied_voxels
from supportnode.params import ObjectParams

# Voxel clustering uses a dense voxel -> id map up to this many grid cells per point (or this
# many cells in all): 2 M cells is a 6 x 5 x 2.5 m room at 3 cm, 10 MB of int32.
_DENSE_CELLS_PER_POINT = 64
_DENSE_MIN_CELLS = 4_000_000


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
    from scipy.spatial import cKDTree  # here: ~0.18 s to import

    tree = cKDTree(sample)
    k = min(params.k, n_s - 1)
    # Imported here: a fresh detect that clusters by voxels (the default) never loads csgraph.
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

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
        stats["_voxel_of_point"] = np.zeros(0, np.int64)  # nothing for convexity either
        return np.zeros(0, dtype=np.int64)
    # +1: a one-voxel empty border, so a neighbour offset can never wrap into the next row.
    keys, dims = grid_keys(cp, voxel_size)
    strides = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
    cells = int(dims.prod())
    if cells <= max(_DENSE_MIN_CELLS, _DENSE_CELLS_PER_POINT * m):
        # A dense voxel -> id map: the voxels' links are followed in compiled code.
        vkeys, occupied, vid, of_point, vsup = occupied_voxels(keys, cells, support)
        nv = len(vkeys)
        comp, cuts = label_voxel_grid(vkeys, occupied, vid, FORWARD_26 @ strides, vsup)
    else:
        # Too large to map densely: the links as edge lists, by sorting.
        nv, of_point, r, c = _voxel_links_sorted(keys, strides)
        cuts = 0
        if support is not None:
            vsup = _highest_support(nv, of_point, support)
            same = vsup[r] == vsup[c]
            cuts = int((~same).sum())
            r, c = r[same], c[same]
        comp = label_edges(nv, r, c)  # numbered as scipy's connected_components, compiled
    stats["voxels"] = int(nv)
    if support is not None:
        stats["support_cuts"] = int(cuts)
    stats["_voxel_of_point"] = of_point  # for the convex method's density test
    return comp[of_point]


def _highest_support(nv: int, of_point: np.ndarray, support: np.ndarray) -> np.ndarray:
    """(V,) int64 highest surface id under the points of each voxel (of_point (M,) voxel,
    support (M,) surface per point, -1 none); -1 where none."""
    vsup = np.full(nv, -1, dtype=np.int64)
    # One assignment per surface, lowest first (the last write stays): np.maximum.at
    # over the points took several ms on a lidar scan.
    for sid in np.flatnonzero(np.bincount(support + 1)) - 1:
        if sid >= 0:
            vsup[of_point[support == sid]] = sid
    return vsup


def _voxel_links_sorted(
    keys: np.ndarray, strides: np.ndarray
) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """Voxels and 26-neighbour links of the points' voxel keys (M,) int64 (strides (3,), an
    empty border around), by np.unique and searchsorted: the number of voxels V, the voxel of
    each point (M,) int64 (voxels numbered in key order) and the links (E,) rows, (E,)
    columns."""
    rows, cols = [], []
    vkeys, inv = np.unique(keys, return_inverse=True)
    nv = len(vkeys)
    inv = inv.ravel()
    for off in FORWARD_26 @ strides:
        pos = np.searchsorted(vkeys, vkeys + off)
        pos = np.minimum(pos, nv - 1)
        hit = np.flatnonzero(vkeys[pos] == vkeys + off)
        rows.append(hit)
        cols.append(pos[hit])
    return nv, inv, np.concatenate(rows), np.concatenate(cols)


def _drop_small(lab: np.ndarray, min_points: int, more: np.ndarray | None = None) -> np.ndarray:
    """Relabel to 0..K-1 keeping components with >= min_points points; others become -1.
    more: (Q,) labels of points that will join the components (counted, not relabelled)."""
    if len(lab) == 0 or lab.max() < 0:
        return np.full(len(lab), -1, dtype=np.int64)
    # Counting instead of np.unique: no sort, and kept labels stay in ascending order; label
    # -1 counted first, then mapped by the table's last entry: one gather, no masks.
    counts = np.bincount(lab + 1)[1:]
    if more is not None and len(more):
        counts += np.bincount(more + 1, minlength=len(counts) + 1)[1 : len(counts) + 1]
    keep = counts >= min_points
    new_id = np.full(len(counts) + 1, -1, dtype=np.int64)
    new_id[:-1][keep] = np.arange(int(keep.sum()))
    return new_id[lab]


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
    # Grouped by label (a counting sort, stable): each cluster's points a contiguous run, in
    # input order; with each cluster's box.
    groups = group_rows(cp, lab, n)
    bounds, _, in_clusters, mins, maxs = groups
    counts = np.diff(bounds)
    present = np.flatnonzero(counts > 0)
    # Ties in size broken by the lowest corner: invariant to point order and to translation.
    order = present[
        np.lexsort((mins[present, 2], mins[present, 1], mins[present, 0], -counts[present]))
    ]
    new_id = np.full(n + 1, -1, dtype=np.int64)  # the last, -1, is label -1's: one gather
    new_id[order] = np.arange(len(order))
    out = new_id[lab]
    # Each cluster's run of in_clusters, in the new order.
    runs = np.stack([bounds[order], bounds[order + 1]], axis=1)
    if known is None:
        sids = _supports(in_clusters, runs, lookups, params.support_tolerance)
    else:
        sids = np.full(len(order), -2, dtype=np.int64)
        have = order < len(known)
        sids[have] = known[order[have]]
        todo = np.flatnonzero(sids == -2)
        # A cluster's surface depends on its points alone: only the new ones are looked up.
        sids[todo] = _supports(in_clusters, runs[todo], lookups, params.support_tolerance)
    return Segmentation(
        out,
        sids,
        mins[order],
        maxs[order],
        _grouped=in_clusters,
        _runs=runs,
        _heights={lk.id: lk.height for lk in lookups},
        _groups=groups,
    )
