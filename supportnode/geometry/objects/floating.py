"""Nothing floats: a segment held by nothing level belongs to what it meets.

Local convexity parts a bottle's neck from its shoulder (they meet in a concave crease, as a
box meets the box it stands on). A box standing on a box rests on the lower box's level
top; the neck rests on nothing: its lowest cells are well above the surface, and the cells
it meets below it lie on a sloped face (the shoulder). A segment that neither comes down to
its surface nor meets a level face below it cannot stand there by itself, so it joins the
segment below it whose sloped faces it meets along the most links. Pure: numpy in, labels out.
"""

from __future__ import annotations

import numpy as np

from supportnode.kernels.components import label_edges
from supportnode.kernels.groups import label_boxes

# A segment comes down to its surface when a cell lies within this of it, metres.
_REACH = 0.02
# A face is level within this angle of +z, degrees.
_LEVEL_DEG = 15.0
# A segment rests on a neighbour when at least this many links lead down to the
# neighbour's level cells.
_REST_LINKS = 3
# It is held by a neighbour when at least this many links lead down to the neighbour's
# sloped cells.
_HELD_LINKS = 5
# It stands above a neighbour whose highest cell is at most this above its lowest, metres.
_BELOW = 0.01


def join_floating(
    centroid: np.ndarray,
    above: np.ndarray,
    face: np.ndarray,
    face_up: np.ndarray,
    seg: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
) -> np.ndarray:
    """(F,) segment of each cell, the segments held by nothing joined to the neighbour whose
    sloped faces below them they meet along the most links (see the module). centroid: (F, 3) cells' centroids, metres, z
    up; above: (F,) their height above the surface under them (inf over none); face: (F,)
    face of each cell (-1: none); face_up: (n_faces,) |z| of each face's normal; seg: (F,)
    segment of each cell (-1: none); src, dst: (L,) adjacent cells."""
    on = seg >= 0
    if not on.any() or len(face_up) == 0:
        return seg
    n = int(seg.max()) + 1
    # Per segment in one compiled pass: the lowest height above the surface, the lowest and
    # highest centroid (np.minimum.at / np.maximum.at, ~50 us a call, the same values).
    lo, hi = label_boxes(np.stack([above, centroid[:, 2]], axis=1), seg, n)
    low = lo[:, 0]
    # Over no surface (inf) nothing is known; on the surface it stands by itself.
    aloft = np.isfinite(low) & (low > _REACH)
    if not aloft.any():
        return seg
    a = np.concatenate([src, dst])
    b = np.concatenate([dst, src])
    sa, sb = seg[a], seg[b]
    between = (sa >= 0) & (sb >= 0) & (sa != sb)
    a, b, sa, sb = a[between], b[between], sa[between], sb[between]
    level = face_up >= np.cos(np.radians(_LEVEL_DEG))
    fb = face[b]
    lower = (fb >= 0) & (centroid[b, 2] < centroid[a, 2])
    on_level = level[np.maximum(fb, 0)]
    rests = np.bincount(sa[lower & on_level], minlength=n) >= _REST_LINKS
    floating = aloft & ~rests
    # It joins what it stands above: its lowest cell no lower than that one's highest (a
    # neck on a shoulder), not what it stands beside (a cup's inner wall beside its outer).
    bottom, top = lo[:, 1], hi[:, 1]
    # ... and what holds it stands: on its surface or on a level face (a row of things over
    # a shelf board the surfaces missed floats as a whole, and proves nothing).
    # The links that show it held: down to that one's sloped faces (a neck's whole rim on a
    # shoulder), not a link or two where the view shows little of what is under it.
    pick = lower & ~on_level & floating[sa] & ~floating[sb] & (bottom[sa] >= top[sb] - _BELOW)
    if not pick.any():
        return seg
    pair, links = np.unique(sa[pick] * n + sb[pick], return_counts=True)
    pair, links = pair[links >= _HELD_LINKS], links[links >= _HELD_LINKS]
    if len(pair) == 0:
        return seg
    order = np.lexsort((-links, pair // n))
    first = order[np.r_[True, (pair // n)[order][1:] != (pair // n)[order][:-1]]]
    best = pair[first]
    joined = label_edges(n, best // n, best % n)
    return np.where(on, joined[np.maximum(seg, 0)], -1)
