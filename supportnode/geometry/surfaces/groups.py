"""Graph components and per-group medians, shared by the growth and the filters."""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components


def _components(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Connected-component label of each of n nodes given undirected edges (components
    numbered by their first node, whatever the order of the edges)."""
    # The CSR arrays directly, in the dtypes csgraph works in: from a COO matrix, scipy's
    # conversions and checks cost twice the search on graphs of a few thousand edges.
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.bincount(src, minlength=n), out=indptr[1:])
    order = np.argsort(src, kind="stable")
    graph = csr_matrix((np.ones(len(src)), dst[order].astype(np.int32), indptr), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    return comp


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
