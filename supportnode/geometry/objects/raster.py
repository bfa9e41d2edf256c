"""2-D bool raster operations of the footprint splits (hole filling, 3 x 3 closing and
labelling are compiled, in `supportnode.kernels.footprint`): taxicab depth test, bounding box of the set cells and the
Euclidean distance transform.

Rasters are (H, W) bool arrays, True = occupied; distances are in cells. Each function gives
the same result as the scipy.ndimage call named in its docstring, faster on the large, nearly
empty footprint rasters of wall clusters.
"""

from __future__ import annotations

import numpy as np

from supportnode.kernels.morphology import distance_transform

# _edt_inner works on the occupied cells only of rasters of at least this many cells, at most
# _EDT_SPARSE_MAX_FILL of them occupied (a ring of walls: 2-4 %); the whole transform on the rest.
_EDT_SPARSE_MIN_CELLS = 16_384
_EDT_SPARSE_MAX_FILL = 0.125


def _taxicab_deep(mask: np.ndarray, cell: float, limit: float) -> bool:
    """Whether ``(distance_transform_cdt(mask, "taxicab").max() - 0.5) * cell >= limit`` for a
    2-D bool mask whose outer rows and columns are empty.

    A cell is at taxicab distance >= k from the background iff it survives k - 1 erosions by
    the 4-neighbour cross; the expression grows with k, so erosion stops at the first k that
    reaches limit (a few erosions) or when nothing is left (then k - 1 was the maximum).
    """
    cur, k = mask, 1
    while cur.any():  # some cell is at distance >= k
        if (k - 0.5) * cell >= limit:
            return True
        ero = np.zeros_like(cur)
        ero[1:-1, 1:-1] = (
            cur[1:-1, 1:-1] & cur[:-2, 1:-1] & cur[2:, 1:-1] & cur[1:-1, :-2] & cur[1:-1, 2:]
        )
        cur, k = ero, k + 1
    return False


def _true_box(mask: np.ndarray) -> tuple[slice, slice]:
    """The smallest box (row slice, column slice) holding the True cells of a 2-D bool mask;
    the whole mask when it has none."""
    rows = np.flatnonzero(mask.any(axis=1))
    if len(rows) == 0:
        return slice(0, mask.shape[0]), slice(0, mask.shape[1])
    cols = np.flatnonzero(mask.any(axis=0))
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def _edt_inner(mask: np.ndarray, count: int | None = None) -> np.ndarray:
    """``ndimage.distance_transform_edt(mask)`` (H, W) float64, cells, of a 2-D bool mask whose
    outer rows and columns are empty; the same values. count: ``mask.sum()`` when known.

    A room-sized cluster of walls has a big, nearly empty footprint raster, where scipy's
    transform costs ~40 ns per cell (5-12 ms). On a raster of at least _EDT_SPARSE_MIN_CELLS
    cells, at most _EDT_SPARSE_MAX_FILL of them occupied, the distance is taken at the occupied
    cells only, separably: the distance to the nearest empty cell in the same column (from the
    column's runs of occupied cells), then the least ``g(i, j +- d)^2 + d^2`` over growing
    column offsets d, each cell dropping out once d^2 reaches its best. That minimum is the
    exact squared distance, an integer; its sqrt is what scipy takes of the same integer.
    """
    h, w = mask.shape
    if count is None:
        count = int(np.count_nonzero(mask))
    if mask.size < _EDT_SPARSE_MIN_CELLS or count > _EDT_SPARSE_MAX_FILL * mask.size:
        return distance_transform(mask)
    out = np.zeros(h * w)
    if count == 0:
        return out.reshape(h, w)
    # Column-major flat indices j * h + i: a run of consecutive ones is a run down a column,
    # never across two (the first and last rows are empty).
    cm = np.flatnonzero(mask.T)
    brk = np.empty(len(cm), dtype=bool)
    brk[0] = True
    np.not_equal(cm[1:], cm[:-1] + 1, out=brk[1:])
    start = np.flatnonzero(brk)
    length = np.diff(start, append=len(cm))
    pos = np.arange(len(cm)) - np.repeat(start, length)  # 0 at a run's first cell
    g = np.minimum(pos + 1, np.repeat(length, length) - pos)  # to the empty cell above / below
    j, i = np.divmod(cm, h)
    flat = i * w + j
    col_dist = np.zeros(h * w, dtype=np.int32)  # 0 at empty cells; int32: fewer pages touched
    col_dist[flat] = g
    d2 = g * g
    # Offset d never reaches past the empty first or last column: a cell d columns from it has
    # d2 <= d^2 and drops out before.
    cand = np.flatnonzero(d2 > 1)
    d = 1
    while len(cand):
        f = flat[cand]
        near = np.minimum(col_dist[f - d], col_dist[f + d]).astype(np.int64)
        best = np.minimum(d2[cand], near * near + d * d)
        d2[cand] = best
        d += 1
        cand = cand[best > d * d]  # offsets >= d give at least d^2
    out[flat] = np.sqrt(d2.astype(np.float64))
    return out.reshape(h, w)
