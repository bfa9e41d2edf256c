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
