"""Graph components and per-group medians, shared by the growth and the filters."""

from __future__ import annotations

import numpy as np

from supportnode.kernels.components import label_edges


def _components(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Connected-component label (int64) of each of n nodes given undirected edges
    (components numbered by their first node, whatever the order of the edges): the
    compiled union-find, scipy's numbering without building a sparse matrix."""
    return label_edges(n, src, dst)


def _median_by_group(values: np.ndarray, groups: np.ndarray, n: int) -> np.ndarray:
    """Median of ``values`` within each group 0..n-1 (0 for empty groups)."""
    out = np.zeros(n)
    if len(values) == 0:
        return out
    order = np.lexsort((values, groups))
    g, v = groups[order], values[order]
    starts = np.searchsorted(g, np.arange(n))
    ends = np.searchsorted(g, np.arange(n), side="right")
    has = ends > starts
    mid = (starts + ends - 1) // 2
    mid2 = (starts + ends) // 2
    out[has] = 0.5 * (v[mid[has]] + v[np.minimum(mid2[has], len(v) - 1)])
    return out


def columns_per_group(group_of_voxel: np.ndarray, keys: np.ndarray, n: int) -> np.ndarray:
    """(n,) int64: the distinct x, y columns of each group's voxels (group_of_voxel (V,) in
    [0, n) or -1 for none, keys (V, >= 2) int64): the rows of np.unique over (group, x, y),
    counted per group; by one packed int64 key a row where the ranges allow (a sort of
    integers, not of rows)."""
    sv = np.flatnonzero(group_of_voxel >= 0)
    s, x, y = group_of_voxel[sv].astype(np.int64), keys[sv, 0], keys[sv, 1]
    if len(sv) == 0:
        return np.zeros(n, np.int64)
    x, y = x - x.min(), y - y.min()
    nx, ny = int(x.max()) + 1, int(y.max()) + 1
    if n * nx * ny < 2**62:
        packed = np.unique((s * nx + x) * ny + y)
        return np.bincount(packed // (nx * ny), minlength=n)
    rows = np.unique(np.stack([s, x, y], 1), axis=0)
    return np.bincount(rows[:, 0], minlength=n)
