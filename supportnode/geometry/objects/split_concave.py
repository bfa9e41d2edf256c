"""Splitting a cluster along concave creases: touching convex objects (barrels in a
triangle) whose footprint has no neck, as in LCCP (Stein et al. 2014).

Points p (P, 3) float64 metres, z up; voxel edge in metres; parts (P,) int64 by size, 0 = the
largest. See _split_concave.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from supportnode.geometry.linalg import sym3_eigen
from supportnode.geometry.objects.arrays import _col
from supportnode.geometry.objects.neighbours import FORWARD_26
from supportnode.geometry.objects.split_step import _STEP_STAND

# Splitting at concave creases (see _split_concave): voxels with at least _CONCAVE_MIN_POINTS
# points have a normal; a part must hold _CONCAVE_PART_FRACTION of the cluster's points, span
# _CONCAVE_PART_VOXELS voxels across in x and y, and reach within _STEP_STAND of the bottom.
_CONCAVE_MIN_POINTS = 3
_CONCAVE_PART_FRACTION = 0.1
_CONCAVE_PART_VOXELS = 2.0
# Only clusters at most this wide in x and y are tried (groups of objects, not room structure).
_CONCAVE_MAX_EXTENT = 1.0


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
    voxels = _voxel_normals(q, voxel)
    if voxels is None:
        return None
    vkeys, strides, inv, cnt, cen, normal = voxels
    comp = _crease_components(vkeys, strides, cnt >= _CONCAVE_MIN_POINTS, cen, normal, tol)
    if comp is None:
        return None
    pcomp = comp[inv]
    ok = pcomp >= 0
    n_comp = int(comp.max()) + 1
    size = np.bincount(pcomp[ok], minlength=n_comp)
    cand = np.flatnonzero(size >= max(min_points, _CONCAVE_PART_FRACTION * len(p)))
    if len(cand) < 2:
        return None
    parts = _standing_parts(q, pcomp, cand, voxel)
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


def _voxel_normals(
    q: np.ndarray, voxel: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The voxels of edge voxel (m) of the centred points q (P, 3): their sorted keys (V,)
    int64, the key strides (3,), the voxel of each point (P,), point counts (V,) float64,
    centroids (V, 3) and unit normals (V, 3) (smallest eigenvector of the points' scatter,
    turned away from the origin, the cluster's centroid); None for fewer than 3 voxels."""
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
    return vkeys, strides, inv, cnt, cen, normal


def _crease_components(
    vkeys: np.ndarray,
    strides: np.ndarray,
    good: np.ndarray,
    cen: np.ndarray,
    normal: np.ndarray,
    tol: float,
) -> np.ndarray | None:
    """(V,) component of each voxel (see _voxel_normals) once the voxels of concave links
    between good (V,) bool voxels are removed, -1 for those; None when no link is concave."""
    nv = len(vkeys)
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
    # Imported here: only a concave split gets this far; most detects never load csgraph.
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(int(keep.sum()), dtype=np.int8), (r[keep], c[keep])), (nv, nv))
    _, comp = connected_components(graph.tocsr(), directed=False)
    comp[crease] = -1
    return comp


def _standing_parts(
    q: np.ndarray, pcomp: np.ndarray, cand: np.ndarray, voxel: float
) -> list[np.ndarray]:
    """The point rows (P_k,) of each candidate component cand of pcomp (P,) (the component of
    each point of q (P, 3)) that spans _CONCAVE_PART_VOXELS voxels in x and y and reaches
    within _STEP_STAND of the cluster's bottom."""
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
    return parts
