"""Splitting a cluster along concave creases: touching convex objects (barrels in a
triangle) whose footprint has no neck, as in LCCP (Stein et al. 2014).

Two rules on the cluster's voxels: the parts left once the voxels of concave links are
removed (_split_concave, off by default: it needs dense sampling), and the walls left once
the tops are removed too (_split_walls, for the sparse clusters that convexity does not
segment: the tops of touching objects of one height join across their contact).

Points p (P, 3) float64 metres, z up; voxel edge in metres; parts (P,) int64 by size, 0 = the
largest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.geometry.linalg import sym3_eigen
from supportnode.geometry.nearest import nearest
from supportnode.geometry.objects.arrays import _col
from supportnode.geometry.objects.hull import footprint_equations, footprint_ring
from supportnode.geometry.objects.neighbours import FORWARD_26
from supportnode.geometry.objects.split_step import _STEP_STAND
from supportnode.kernels.components import label_edges

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
    return None if len(parts) < 2 else _nearest_seed(q, parts, min_points)


def _nearest_seed(q: np.ndarray, parts: list[np.ndarray], min_points: int) -> np.ndarray | None:
    """(P,) part of each point of q (P, 3): that of the nearest point in x, y among the seed
    rows ``parts`` (one array per part), numbered by size (0 the largest); None when a part
    holds fewer than min_points."""
    seed = np.concatenate(parts)
    seed_part = np.repeat(np.arange(len(parts)), [len(s) for s in parts])
    near = nearest(q[seed, :2], q[:, :2])
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
    r, c = _links(vkeys, strides)
    concave = _concave(r, c, good, cen, normal, tol)
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


def _links(vkeys: np.ndarray, strides: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The links (E,), (E,) between 26-neighbouring voxels of the sorted keys vkeys (V,) with
    key strides (3,): each pair once."""
    nv = len(vkeys)
    rows, cols = [], []
    for off in FORWARD_26 @ strides:  # 13 vectorised look-ups, not a loop over voxels
        pos = np.minimum(np.searchsorted(vkeys, vkeys + off), nv - 1)
        hit = np.flatnonzero(vkeys[pos] == vkeys + off)
        rows.append(hit)
        cols.append(pos[hit])
    return np.concatenate(rows), np.concatenate(cols)


def _concave(
    r: np.ndarray,
    c: np.ndarray,
    good: np.ndarray,
    cen: np.ndarray,
    normal: np.ndarray,
    tol: float,
) -> np.ndarray:
    """(E,) bool: which links r, c (E,) between good (V,) voxels are concave, ``(n_r - n_c) .
    (c_r - c_c) < -tol * |c_r - c_c|`` (centroids cen, unit normals normal, (V, 3))."""
    dc = cen[r] - cen[c]
    conv = ((normal[r] - normal[c]) * dc).sum(axis=1)
    return good[r] & good[c] & (conv < -tol * np.sqrt((dc * dc).sum(axis=1)))


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


# Walls (see _split_walls): a voxel whose normal is within acos(_TOP_COS) (37 degrees) of
# vertical is a top, left out; a part's wall holds _WALL_FRACTION of the cluster's points (and
# min_points), spans _WALL_SPAN voxels in x and y (a mug's handle, 3 cm across, does too) and
# has _WALL_OUTER of its points within half a voxel of the cluster's x, y hull.
_TOP_COS = 0.8
_WALL_FRACTION = 0.03
_WALL_SPAN = 0.5
_WALL_OUTER = 0.25
# The parts' walls meet in a crease: of the links between their wall voxels, at least this
# many and this share are concave.
_WALL_CREASE_LINKS = 3
_WALL_CREASE_SHARE = 0.2


@dataclass
class _Voxels:
    """A cluster's voxels (see _voxel_normals) and their links: each point's voxel inv (P,),
    which voxels have a normal (good), are tops, and which links r, c (E,) are concave."""

    inv: np.ndarray
    good: np.ndarray
    top: np.ndarray
    r: np.ndarray
    c: np.ndarray
    concave: np.ndarray


def _split_walls(p: np.ndarray, voxel: float, tol: float, min_points: int) -> np.ndarray | None:
    """(P,) part index per point of p (P, 3) seeded by its walls, else None.

    Touching objects of one height (three barrels in a triangle, two cans 1 cm apart in a
    sparse cloud) have flat tops that join across their contact, so the crease rule (see
    _split_concave) finds one part; their walls still meet only in concave creases. The voxels
    of edge ``voxel`` (m) of concave links and the tops (normal near vertical) are left out;
    the walls' connected components that stand on the cluster's bottom (see _standing_parts),
    show on the cluster's outside (see _outer) and meet the others in a crease seed the
    parts. The seeds grow over smooth links (see _grow); every other point goes to the part
    of the nearest grown point in x, y. Parts by size, each with min_points; None for fewer
    than two.
    """
    if len(p) < 2 * max(min_points, 1):
        return None
    q = p - _col(np.add, p) / len(p)  # centred: moments without cancellation; centroid 0
    found = _wall_voxels(q, voxel, tol)
    if found is None:
        return None
    vox, comp = found
    pcomp = comp[vox.inv]
    size = np.bincount(pcomp[pcomp >= 0], minlength=int(comp.max()) + 1)
    cand = np.flatnonzero(size >= max(min_points, _WALL_FRACTION * len(p)))
    if len(cand) < 2:
        return None
    parts = _standing_parts(q, pcomp, cand, voxel * _WALL_SPAN / _CONCAVE_PART_VOXELS)
    parts = _outer(q[:, :2], parts, voxel)
    if len(parts) < 2:
        return None
    # The tops grow from their own rims: two cans' tops meet only at their contact.
    vseed = np.full(len(comp), -1, np.int64)
    for k, rows in enumerate(parts):
        vseed[vox.inv[rows]] = k
    crease = np.zeros(len(comp), dtype=bool)
    crease[vox.r[vox.concave]] = True
    crease[vox.c[vox.concave]] = True
    smooth = vox.good[vox.r] & vox.good[vox.c] & ~crease[vox.r] & ~crease[vox.c]
    grown = _grow(vseed, vox.r[smooth], vox.c[smooth])[vox.inv]
    part = _nearest_seed(q, [np.flatnonzero(grown == k) for k in range(len(parts))], min_points)
    return part if part is not None and _meet_in_crease(vox, part) else None


def _wall_voxels(q: np.ndarray, voxel: float, tol: float) -> tuple[_Voxels, np.ndarray] | None:
    """The voxels of edge voxel (m) of the centred points q (P, 3) and the component (V,) of
    each among the walls: voxels with a normal, neither tops nor on a concave link (-1 for
    the rest); None without voxels or concave links."""
    voxels = _voxel_normals(q, voxel)
    if voxels is None:
        return None
    vkeys, strides, inv, cnt, cen, normal = voxels
    good = cnt >= _CONCAVE_MIN_POINTS
    r, c = _links(vkeys, strides)
    concave = _concave(r, c, good, cen, normal, tol)
    if not concave.any():
        return None
    top = good & (np.abs(normal[:, 2]) > _TOP_COS)
    out = ~good | top
    out[r[concave]] = True
    out[c[concave]] = True
    keep = ~out[r] & ~out[c]
    comp = label_edges(len(vkeys), r[keep], c[keep])
    comp[out] = -1
    return _Voxels(inv, good, top, r, c, concave), comp


def _meet_in_crease(vox: _Voxels, part: np.ndarray) -> bool:
    """Whether the parts (P,) of the points meet in a crease: sparse voxels (too few points
    for a normal) break a wall too, and one box's sides, cut where its sampling thins out,
    meet in a smooth wall. Each voxel is in the part of most of its points."""
    votes = np.zeros((len(vox.good), int(part.max()) + 1))
    np.add.at(votes, (vox.inv, part), 1.0)
    vpart = votes.argmax(axis=1)
    r, c = vox.r, vox.c
    across = vox.good[r] & vox.good[c] & ~vox.top[r] & ~vox.top[c] & (vpart[r] != vpart[c])
    n_concave = int(np.count_nonzero(vox.concave & across))
    return n_concave >= _WALL_CREASE_LINKS and n_concave >= _WALL_CREASE_SHARE * across.sum()


def _grow(vseed: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(V,) part of each node: the seeds' vseed (V,) (-1: none) grown breadth first over the
    links r, c (E,), all parts a step at a time (a node reached by two parts in one step goes
    to the lower-numbered); -1 where no part reaches."""
    part = vseed.copy()
    a, b = np.concatenate([r, c]), np.concatenate([c, r])  # both directions
    while True:
        reach = (part[a] >= 0) & (part[b] < 0)
        if not reach.any():
            return part
        node, src = b[reach], part[a[reach]]
        order = np.lexsort((src, node))
        node, src = node[order], src[order]
        first = np.r_[True, node[1:] != node[:-1]]
        part[node[first]] = src[first]


def _outer(xy: np.ndarray, parts: list[np.ndarray], voxel: float) -> list[np.ndarray]:
    """The parts (point rows into xy (P, 2), metres) with _WALL_OUTER of their points within
    half a voxel of the x, y convex hull's edge: each object of a touching group shows the
    group an outer wall; the inner arc of a barrel in a triangle, between its two contacts,
    is the same barrel's wall."""
    ring = footprint_ring(xy)
    if ring is None:  # all on a line: no wall to show
        return []
    eq = footprint_equations(ring)  # (F, 3): n . p + d <= 0 inside, |n| = 1
    out = []
    for rows in parts:  # only the seeds' points: a wall cluster holds 100k
        seed = np.take(xy, rows, axis=0)
        edge = (seed @ eq[:, :2].T + eq[:, 2]).max(axis=1) >= -0.5 * voxel
        if edge.mean() >= _WALL_OUTER:
            out.append(rows)
    return out
