"""Helpers of `cellgraph`'s window sums: a dense table of the grid's columns, and rows of
moments added in registers. No supportnode imports (`cellgraph` imports this)."""

from __future__ import annotations

import numpy as np
from numba import njit

# A dense table of the columns only up to this many entries per cell (else hashed lookups).
_DENSE_PER_CELL = 64
# Rows this wide are summed in registers (cellgraph.MOMENTS: count, x, y, z, six products).
_UNROLLED = 10


@njit(cache=True, nogil=True)
def dense_columns(ijk, start, cells, w):
    """The columns' ids in a dense (i, j) table padded by ``w``: (table, i0, j0, width), -1
    for no column; an empty table when the cells' box is too sparse for one."""
    n = ijk.shape[0]
    i0 = j0 = np.int64(1) << 62
    i1 = j1 = -i0
    for c in range(n):
        i0, i1 = min(i0, ijk[c, 0]), max(i1, ijk[c, 0])
        j0, j1 = min(j0, ijk[c, 1]), max(j1, ijk[c, 1])
    width = j1 - j0 + 1 + 2 * w
    rows = i1 - i0 + 1 + 2 * w
    if n == 0 or rows * width > max(1 << 16, _DENSE_PER_CELL * n):
        return np.empty(0, np.int32), 0, 0, 0
    table = np.full(rows * width, -1, np.int32)
    for q in range(start.size - 1):
        c = cells[start[q]]
        table[(ijk[c, 0] - i0 + w) * width + ijk[c, 1] - j0 + w] = q
    return table, i0 - w, j0 - w, width


@njit(cache=True, nogil=True)
def add_rows(mom, idx, n, row):
    """row += rows idx[:n] of mom (M,) wide, one after the other: each column's sum in a
    register for M = 10 (through the row in memory, each addition waited on the last one's
    store), the same additions in the same order."""
    if mom.shape[1] != _UNROLLED:
        for t in range(n):
            for e in range(mom.shape[1]):
                row[e] += mom[idx[t], e]
        return
    s0, s1, s2, s3, s4 = row[0], row[1], row[2], row[3], row[4]
    s5, s6, s7, s8, s9 = row[5], row[6], row[7], row[8], row[9]
    for t in range(n):
        j = idx[t]
        s0 += mom[j, 0]
        s1 += mom[j, 1]
        s2 += mom[j, 2]
        s3 += mom[j, 3]
        s4 += mom[j, 4]
        s5 += mom[j, 5]
        s6 += mom[j, 6]
        s7 += mom[j, 7]
        s8 += mom[j, 8]
        s9 += mom[j, 9]
    row[0], row[1], row[2], row[3], row[4] = s0, s1, s2, s3, s4
    row[5], row[6], row[7], row[8], row[9] = s5, s6, s7, s8, s9
