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
        seg = label_edges(n, key[join] // n, key[join] % n)[seg]
    return seg


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
