"""Faces joined into segments by the votes of their boundaries' links (after LCCP: Stein
et al., CVPR 2014), and slivers absorbed. Pure: numpy in, labels out."""

from __future__ import annotations

import numpy as np

from supportnode.kernels.components import label_edges

# The share of a boundary's links that must be concave for it to separate its faces.
CONCAVE_SHARE = 0.3
# Boundaries of at least this many links join faces first; then segments join across all
# their boundaries pooled, for up to this many rounds (see vote_segments).
_STRONG_LINKS = 20
_VOTE_ROUNDS = 4
# A boundary of at least _STRONG_LINKS links, this share of them concave, is a crease that
# no chain of joins may cross.
_CREASE_SHARE = 0.5


def vote_segments(
    n: int, a: np.ndarray, b: np.ndarray, links: np.ndarray, concave: np.ndarray
) -> np.ndarray:
    """(n,) segment of each face from its boundaries (a, b, links, concave links; (B,)).

    Long boundaries speak first: faces joined across those of at least _STRONG_LINKS links
    that are mostly convex. The segments so made then join across all that lies between
    them, their boundaries' links pooled: a crease of a few links (where a box's face meets
    the corner of the box it stands on) cannot join what a long concave crease parts."""
    convex = concave < CONCAVE_SHARE * links
    strong = links >= _STRONG_LINKS
    crease = strong & (concave >= _CREASE_SHARE * links)
    seg = label_edges(n, a[strong & convex], b[strong & convex])
    for _ in range(_VOTE_ROUNDS):
        sa, sb = np.minimum(seg[a], seg[b]), np.maximum(seg[a], seg[b])
        between = sa != sb
        if not between.any():
            break
        key, inv = np.unique(sa[between] * n + sb[between], return_inverse=True)
        pooled = np.bincount(inv.reshape(-1), weights=links[between])
        pooled_concave = np.bincount(inv.reshape(-1), weights=concave[between])
        join = pooled_concave < CONCAVE_SHARE * pooled
        if not join.any():
            break
        ca, cb = seg[a[crease]], seg[b[crease]]
        apart = (ca[ca != cb], cb[ca != cb])
        seg = _join(n, key[join] // n, key[join] % n, pooled[join], apart)[seg]
    return seg


def _join(
    n: int,
    a: np.ndarray,
    b: np.ndarray,
    weight: np.ndarray,
    apart: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """(n,) component of each node joined by the pairs (a, b) (J,), except that no component
    may hold both ends of a pair in ``apart`` (two (K,) arrays: faces on either side of a
    long concave crease). The joins are taken heaviest first; one that would put a crease
    inside a component is skipped: a sliver in the cusp between two cans meets each can
    convexly, and joining both joins would join across the crease between them."""
    if len(apart[0]) == 0:
        return label_edges(n, a, b)
    parent = list(range(n))
    members: list[set[int]] = [{i} for i in range(n)]
    avoid: list[set[int]] = [set() for _ in range(n)]
    for x, y in zip(apart[0].tolist(), apart[1].tolist(), strict=True):
        avoid[x].add(y)
        avoid[y].add(x)

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for k in np.argsort(-weight, kind="stable").tolist():
        x, y = root(int(a[k])), root(int(b[k]))
        if x == y or avoid[x] & members[y]:
            continue
        if len(members[x]) < len(members[y]):
            x, y = y, x
        parent[y] = x
        members[x] |= members[y]
        avoid[x] |= avoid[y]
    roots = np.array([root(i) for i in range(n)], np.int64)
    return np.unique(roots, return_inverse=True)[1].reshape(-1)


def absorb_small(
    seg: np.ndarray, count: np.ndarray, src: np.ndarray, dst: np.ndarray, min_points: int
) -> np.ndarray:
    """Segments of fewer than ``min_points`` points (count: (F,) points per cell) join the
    other segment they share the most links with (slivers along a crease); those with no
    such neighbour stay."""
    on = seg >= 0
    if not on.any():
        return seg
    size = np.bincount(seg[on], weights=count[on])
    small = size < min_points
    if not small.any():
        return seg
    a = np.concatenate([seg[src], seg[dst]])
    b = np.concatenate([seg[dst], seg[src]])
    pick = (a >= 0) & (b >= 0) & (a != b)
    a, b = a[pick], b[pick]
    pick = small[a] & ~small[b]
    if not pick.any():
        return seg
    n = len(small)
    pair, votes = np.unique(a[pick] * n + b[pick], return_counts=True)
    order = np.lexsort((-votes, pair // n))
    first = np.ones(len(order), bool)
    first[1:] = (pair // n)[order][1:] != (pair // n)[order][:-1]
    best = pair[order][first]
    target = np.arange(n)
    target[best // n] = best % n
    return np.where(on, target[np.maximum(seg, 0)], -1)
