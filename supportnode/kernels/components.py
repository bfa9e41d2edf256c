"""Connected components of a graph given as an edge list: union-find in compiled code."""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True)
def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression: later finds are near O(1)
        parent[i], i = root, parent[i]
    return root


@njit(cache=True)
def _label(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    parent = np.arange(n)
    for e in range(src.size):
        a = _find(parent, src[e])
        b = _find(parent, dst[e])
        if a != b:
            # The smaller index becomes the root: labels then follow each component's
            # smallest member, the same numbering as scipy's connected_components.
            if a < b:
                parent[b] = a
            else:
                parent[a] = b
    labels = np.empty(n, np.int64)
    next_label = 0
    for i in range(n):
        r = _find(parent, i)
        if r == i:
            labels[i] = next_label
            next_label += 1
        else:
            labels[i] = labels[r]  # r < i: already labelled
    return labels


def label_edges(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Component of each of n nodes joined by undirected edges (src[e], dst[e]).

    src, dst: (E,) integer node indices in [0, n). Returns (n,) int64 labels 0..K-1, numbered
    by each component's smallest node (as ``scipy.sparse.csgraph.connected_components``).
    Raises ValueError on edges out of range or arrays of different lengths.
    """
    s = np.ascontiguousarray(src, dtype=np.int64).ravel()
    d = np.ascontiguousarray(dst, dtype=np.int64).ravel()
    if s.shape != d.shape:
        raise ValueError(f"src and dst differ in length: {s.size} and {d.size}")
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    if s.size and (min(s.min(), d.min()) < 0 or max(s.max(), d.max()) >= n):
        raise ValueError(f"edge endpoints must lie in [0, {n})")
    return _label(int(n), s, d)


@warmer
def _warm() -> None:
    label_edges(3, np.array([0]), np.array([2]))
