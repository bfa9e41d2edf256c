"""`cellgraph`'s window sums and their helpers: the grid's columns (a hash table of the
cells' packed keys, Fibonacci hashing and linear probing, and a dense table where the cells'
box allows one), and rows of moments added in registers. No supportnode imports
(`cellgraph` imports this)."""

from __future__ import annotations

import numpy as np
from numba import int64, njit, uint64

GOLDEN = 0x9E3779B97F4A7C15

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


@njit(cache=True, nogil=True, inline="always")
def _home(key: int, shift: int) -> int:
    return int64((uint64(key) * uint64(GOLDEN)) >> uint64(shift))


@njit(cache=True, nogil=True, inline="always")
def _find(tk: np.ndarray, tv: np.ndarray, shift: int, key: int) -> int:
    mask = tk.size - 1
    pos = _home(key, shift)
    while True:
        k = tk[pos]
        if k == key:
            return tv[pos]
        if k == -1:
            return -1
        pos = (pos + 1) & mask


@njit(cache=True, nogil=True)
def _columns(ijk: np.ndarray, dims: np.ndarray) -> tuple:
    # The cells grouped by column (i, j): a lookup table of the columns' packed keys, each
    # column's run [start[col], start[col + 1]) of ``cells``, ascending in k within the run.
    n = ijk.shape[0]
    keys = np.empty(n, np.int64)
    for c in range(n):
        keys[c] = ijk[c, 0] * dims[1] + ijk[c, 1]
    bits = 4
    while (1 << bits) < 2 * max(n, 1):
        bits += 1
    cap = 1 << bits
    shift = 64 - bits
    mask = cap - 1
    tk = np.full(cap, -1, np.int64)
    tv = np.empty(cap, np.int64)
    col = np.empty(n, np.int64)
    count = np.zeros(n + 1, np.int64)
    m = 0
    for c in range(n):  # a column id per column, in order of its first cell
        pos = _home(keys[c], shift)
        while tk[pos] != -1 and tk[pos] != keys[c]:
            pos = (pos + 1) & mask
        if tk[pos] == -1:
            tk[pos] = keys[c]
            tv[pos] = m
            m += 1
        col[c] = tv[pos]
        count[col[c] + 1] += 1
    start = np.empty(m + 1, np.int64)
    start[0] = 0
    for q in range(m):
        start[q + 1] = start[q] + count[q + 1]
    fill = start.copy()
    cells = np.empty(n, np.int64)
    for c in range(n):
        t = fill[col[c]]
        # Insertion into the column's run by k (columns are short: tens of cells).
        while t > start[col[c]] and ijk[cells[t - 1], 2] > ijk[c, 2]:
            cells[t] = cells[t - 1]
            t -= 1
        cells[t] = c
        fill[col[c]] += 1
    return tk, tv, shift, start, cells


@njit(cache=True, nogil=True)
def _window_sums(
    ijk: np.ndarray,
    dims: np.ndarray,
    mom: np.ndarray,
    w: int,
    label: np.ndarray,
    same: bool,
    at: np.ndarray,
) -> np.ndarray:
    # Per cell, the (2w + 1)^2 columns around it, its cells within w in k read in ascending
    # k: the same cells in the same order (dx, dy, dz ascending) as (2w + 1)^3 lookups of
    # single cells, so the same sums to the bit. Cells are taken column by column, in
    # ascending k: a column's neighbour columns are looked up once for all its cells, and in
    # each the first cell at k - w or above only moves up (no bisection per cell). The
    # columns come from a dense table where the cells' box allows one (a row of dy's columns
    # then lies in one or two cache lines), else from hashed lookups.
    tk, tv, shift, start, cells = _columns(ijk, dims)
    dense, di, dj, width = dense_columns(ijk, start, cells, w)
    slot = np.full(ijk.shape[0], -1, np.int64)  # each cell's row of the output, -1: none
    for r in range(at.size):
        if slot[at[r]] >= 0:  # a cell asked for twice: cell by cell
            return _window_sums_each(ijk, dims, mom, w, label, same, at)
        slot[at[r]] = r
    out = np.zeros((at.size, mom.shape[1]))
    # The cells' k and label in column order: read without going through the cell index.
    kk = np.empty(cells.size, np.int64)
    ll = np.empty(cells.size, np.int64)
    for u in range(cells.size):
        kk[u], ll[u] = ijk[cells[u], 2], label[cells[u]]
    side = 2 * w + 1
    idx = np.empty(side**3, np.int64)  # the cells of one window, in order
    nbr = np.empty(side * side, np.int64)  # a column's neighbour columns, -1: none
    ptr = np.empty(side * side, np.int64)  # in each, the first cell not below the window
    for col in range(start.size - 1):
        wanted = False
        for t in range(start[col], start[col + 1]):
            wanted = wanted or slot[cells[t]] >= 0
        if not wanted:
            continue
        c0 = cells[start[col]]
        m = 0
        for dx in range(-w, w + 1):
            for dy in range(-w, w + 1):
                if dense.size:
                    q = dense[(ijk[c0, 0] + dx - di) * width + ijk[c0, 1] + dy - dj]
                else:
                    q = _find(tk, tv, shift, (ijk[c0, 0] + dx) * dims[1] + ijk[c0, 1] + dy)
                nbr[m] = q
                ptr[m] = start[q] if q >= 0 else 0
                m += 1
        for t in range(start[col], start[col + 1]):
            c = cells[t]
            if slot[c] < 0:
                continue
            k_lo, k_hi, own = ijk[c, 2] - w, ijk[c, 2] + w, label[c]
            n = 0
            for m in range(side * side):
                q = nbr[m]
                if q < 0:
                    continue
                p, end = ptr[m], start[q + 1]
                while p < end and kk[p] < k_lo:
                    p += 1
                ptr[m] = p
                while p < end and kk[p] <= k_hi:
                    idx[n] = cells[p]
                    n += not same or ll[p] == own
                    p += 1
            add_rows(mom, idx, n, out[slot[c]])
    return out


@njit(cache=True, nogil=True)
def _window_sums_each(
    ijk: np.ndarray,
    dims: np.ndarray,
    mom: np.ndarray,
    w: int,
    label: np.ndarray,
    same: bool,
    at: np.ndarray,
) -> np.ndarray:
    # `_window_sums` cell by cell, each cell's columns looked up by hash and bisected: for
    # cells asked for more than once.
    tk, tv, shift, start, cells = _columns(ijk, dims)
    out = np.zeros((at.size, mom.shape[1]))
    idx = np.empty((2 * w + 1) ** 3, np.int64)
    for r in range(at.size):
        c = at[r]
        k_lo, k_hi = ijk[c, 2] - w, ijk[c, 2] + w
        n = 0
        for dx in range(-w, w + 1):
            for dy in range(-w, w + 1):
                q = _find(tk, tv, shift, (ijk[c, 0] + dx) * dims[1] + ijk[c, 1] + dy)
                if q < 0:
                    continue
                lo, hi = start[q], start[q + 1]
                while lo < hi:
                    mid = (lo + hi) >> 1
                    if ijk[cells[mid], 2] < k_lo:
                        lo = mid + 1
                    else:
                        hi = mid
                for t in range(lo, start[q + 1]):
                    j = cells[t]
                    if ijk[j, 2] > k_hi:
                        break
                    if not same or label[j] == label[c]:
                        idx[n] = j
                        n += 1
        add_rows(mom, idx, n, out[r])
    return out
