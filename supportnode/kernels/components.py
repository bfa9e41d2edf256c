"""Connected components in compiled code (union-find): of a graph given as an edge list, and
of the occupied voxels of a dense grid."""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True)
def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression: later finds are near O(1)
        parent[i], i = root, parent[i]
    return root


@njit(cache=True, nogil=True)
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
    return _numbered(parent)


@njit(cache=True, nogil=True)
def _numbered(parent: np.ndarray) -> np.ndarray:
    # Components numbered by their smallest member, which is each root (see _label).
    n = parent.size
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


@njit(cache=True, nogil=True)
def _label_grid(
    vkeys: np.ndarray,
    occupied: np.ndarray,
    vid: np.ndarray,
    offsets: np.ndarray,
    vsup: np.ndarray,
) -> tuple[np.ndarray, int]:
    n = vkeys.size
    parent = np.arange(n)
    cuts = 0
    for v in range(n):
        for off in offsets:
            nb = vkeys[v] + off
            if not occupied[nb]:
                continue
            u = vid[nb]
            if vsup.size and vsup[u] != vsup[v]:
                cuts += 1
                continue
            a, b = _find(parent, v), _find(parent, u)
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b
    return _numbered(parent), cuts


def label_voxel_grid(
    vkeys: np.ndarray,
    occupied: np.ndarray,
    vid: np.ndarray,
    offsets: np.ndarray,
    support: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """Components of the occupied voxels of a dense grid joined along ``offsets``.

    vkeys: (V,) int64 flat keys of the occupied voxels, ascending; occupied: (cells,) bool;
    vid: (cells,) integer voxel index at each occupied key (other entries never read);
    offsets: (K,) int64 flat key offsets (one of each opposite pair), with an empty border
    around the grid so that no offset leaves it; support: optional (V,) int64 label per
    voxel: voxels of different labels are not joined. Returns (V,) int64 components
    numbered by their smallest voxel (as ``label_edges``) and the number of links cut by
    ``support``.
    """
    keys = np.ascontiguousarray(vkeys, dtype=np.int64)
    offs = np.ascontiguousarray(offsets, dtype=np.int64).ravel()
    if keys.size and (
        keys.min() + min(offs.min(), 0) < 0 or keys.max() + max(offs.max(), 0) >= occupied.size
    ):
        raise ValueError("a voxel's neighbour lies outside the grid: leave an empty border")
    sup = np.zeros(0, np.int64) if support is None else np.ascontiguousarray(support, np.int64)
    if support is not None and sup.shape != keys.shape:
        raise ValueError(f"support must have one label per voxel ({keys.size}), got {sup.size}")
    return _label_grid(keys, np.ascontiguousarray(occupied), np.ascontiguousarray(vid), offs, sup)


@warmer
def _warm() -> None:
    label_edges(3, np.array([0]), np.array([2]))
    occupied = np.array([False, True, True, False])
    vid = np.array([0, 0, 1, 0], np.int32)
    for support in (None, np.array([0, 1])):  # one specialisation: occupied_voxels' int32 ids
        label_voxel_grid(np.array([1, 2]), occupied, vid, np.array([1]), support)
