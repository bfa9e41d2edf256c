"""Shared cells of footprints: the intersection counts behind the trackers' IoU matrix.

The numpy path searched every cell of one side twice in the other's sorted cells and then
expanded the ranges with repeats, an arange and a bincount: a dozen temporaries of all the
cells, on each tracker update. Here each cell is one binary search and a walk over its equal
run. Releases the interpreter lock.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer
from supportnode.kernels.search import first_at

__all__ = ["shared_cells"]


@njit(cache=True, nogil=True)
def _shared(ca, la, cb, lb, na, nb):
    inter = np.zeros((na, nb), np.int64)
    m = cb.size
    for i in range(ca.size):
        c = ca[i]
        row = la[i]
        j = first_at(cb, c, 0)
        while j < m and cb[j] == c:  # a cell in several footprints of b: each counts
            inter[row, lb[j]] += 1
            j += 1
    return inter


def shared_cells(a: list[np.ndarray], b: list[np.ndarray]) -> np.ndarray:
    """(len(a), len(b)) int64: how many cells footprint i of ``a`` and footprint j of ``b``
    share. a, b: lists of (C,) int64 packed cells, each footprint's unique (a cell may lie in
    several footprints of one list)."""
    na, nb = len(a), len(b)
    if na == 0 or nb == 0:
        return np.zeros((na, nb), np.int64)
    size_a = np.array([len(x) for x in a], np.int64)
    size_b = np.array([len(x) for x in b], np.int64)
    ca = np.concatenate([np.asarray(x, np.int64) for x in a])
    la = np.repeat(np.arange(na, dtype=np.int64), size_a)
    cb = np.concatenate([np.asarray(x, np.int64) for x in b])
    order = np.argsort(cb, kind="stable")
    lb = np.repeat(np.arange(nb, dtype=np.int64), size_b)[order]
    return _shared(ca, la, cb[order], lb, na, nb)


@warmer
def _warm() -> None:
    shared_cells([np.array([1, 2], np.int64)], [np.array([2, 3], np.int64), np.array([2])])
