"""Faces that bridge two objects across a concave crease, parted between them.

Two cans touching side by side, or two boxes of one height, have coplanar tops that touch:
region growing (:func:`faces.grow_faces`) makes one face of both, that face meets each
object's side convexly, and so joins what the long concave crease between their sides
parts. LCCP (Stein et al., CVPR 2014) has the same blind spot; CPC (Schoeler et al., CVPR
2015) cuts such a face along a plane. Here a face that meets two faces convexly while they
meet each other along a strongly concave boundary is a bridge: each of its cells goes to
the side it is nearer to through the face (the cut runs between them), and the vote
(`convexity._vote`) decides on the pooled boundary. A cut across a long face (one object's
L-shaped top) counts its many flat links, and joins again unless the crease outweighs it.
Pure: numpy in, labels out.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

# A boundary is a crease when it has at least this many links and this share of them concave.
_CREASE_LINKS = 20
_CREASE_SHARE = 0.5
# A face bridges two creased faces when it meets each along at least this many links.
_BRIDGE_LINKS = 5


def split_bridges(
    face: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    concave: np.ndarray,
    convex_share: float,
) -> np.ndarray:
    """(F,) face of each cell, bridging faces parted (a part takes a new label; the largest
    keeps the face's own). face: (F,) cell labels, -1 none; src, dst: (L,) adjacent cells;
    concave: (L,) bool, a link between two faces judged concave (False within a face);
    convex_share: a boundary with fewer concave links than this share is convex."""
    fa, fb = face[src], face[dst]
    on = (fa >= 0) & (fb >= 0) & (fa != fb)
    if not on.any():
        return face
    n = int(face.max()) + 1
    lo, hi = np.minimum(fa[on], fb[on]), np.maximum(fa[on], fb[on])
    pair, inv = np.unique(lo * n + hi, return_inverse=True)
    links = np.bincount(inv.reshape(-1), minlength=len(pair))
    n_conc = np.bincount(inv.reshape(-1), weights=concave[on], minlength=len(pair))
    crease = (links >= _CREASE_LINKS) & (n_conc >= _CREASE_SHARE * links)
    if not crease.any():
        return face
    convex = (links >= _BRIDGE_LINKS) & (n_conc < convex_share * links)
    sides = _bridges(pair[crease] // n, pair[crease] % n, pair[convex] // n, pair[convex] % n)
    out = face.copy()
    fresh = n
    for f, faces_ in sides.items():
        fresh = _part(out, f, sorted(faces_), src, dst, fresh)
    return out


def _bridges(ca: np.ndarray, cb: np.ndarray, va: np.ndarray, vb: np.ndarray) -> dict:
    """{face: the faces it bridges}: faces meeting both faces of a crease (ca, cb) convexly
    (convex boundaries va, vb)."""
    near: dict[int, set[int]] = {}
    for a, b in zip(va.tolist(), vb.tolist(), strict=True):
        near.setdefault(a, set()).add(b)
        near.setdefault(b, set()).add(a)
    sides: dict[int, set[int]] = {}
    for a, b in zip(ca.tolist(), cb.tolist(), strict=True):
        for f in near.get(a, set()) & near.get(b, set()):
            sides.setdefault(f, set()).update((a, b))
    return sides


def _part(
    face: np.ndarray, f: int, sides: list[int], src: np.ndarray, dst: np.ndarray, fresh: int
) -> int:
    """Relabel face f's cells in place by the side (of ``sides``) each is nearest to, in
    links through f; returns the next free label."""
    cells = np.flatnonzero(face == f)
    local = np.full(len(face), -1, np.int64)
    local[cells] = np.arange(len(cells))
    inner = (local[src] >= 0) & (local[dst] >= 0)
    m = len(cells) + len(sides)
    # Graph over f's cells plus one node per side, linked to the cells of f it touches.
    a, b = [local[src[inner]]], [local[dst[inner]]]
    for k, s in enumerate(sides):
        for x, y in ((src, dst), (dst, src)):
            touch = (local[x] >= 0) & (face[y] == s)
            a.append(local[x[touch]])
            b.append(np.full(int(touch.sum()), len(cells) + k))
    i, j = np.concatenate(a), np.concatenate(b)
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(m, m)).tocsr()
    seeds = np.arange(len(cells), m)
    _, _, nearest = dijkstra(
        graph,
        directed=False,
        indices=seeds,
        unweighted=True,
        min_only=True,
        return_predecessors=True,
    )
    side = nearest[: len(cells)] - len(cells)  # negative where no side reaches (scipy: -9999)
    side = np.where(side >= 0, side, -1)
    counts = np.bincount(side[side >= 0], minlength=len(sides))
    if (counts > 0).sum() < 2:
        return fresh
    keep = int(np.argmax(counts))
    for other in np.flatnonzero(counts).tolist():
        if other != keep:
            face[cells[side == other]] = fresh
            fresh += 1
    return fresh
