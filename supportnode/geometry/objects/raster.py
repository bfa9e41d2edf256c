"""2-D bool raster operations of the footprint splits and the support look-up: hole filling,
hole counting, 3 x 3 closing, taxicab depth test, bounding box of the set cells and the
Euclidean distance transform.

Rasters are (H, W) bool arrays, True = occupied; distances are in cells. Each function gives
the same result as the scipy.ndimage call named in its docstring, faster on the large, nearly
empty footprint rasters of wall clusters.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

# _edt_inner works on the occupied cells only of rasters of at least this many cells, at most
# _EDT_SPARSE_MAX_FILL of them occupied (a ring of walls: 2-4 %); scipy's on the rest.
_EDT_SPARSE_MIN_CELLS = 16_384
_EDT_SPARSE_MAX_FILL = 0.125
# _fill_holes first counts the holes (see _hole_count) on rasters of at least this many cells:
# a wall cluster's footprint (a thin ring, open at a door) usually has none.
_FILL_CHECK_MIN_CELLS = 65_536


def _fill_holes(mask: np.ndarray, max_cells: int | None = None) -> np.ndarray:
    """``ndimage.binary_fill_holes(mask)`` for a 2-D mask, by one labelling of the background;
    with ``max_cells``, only holes of at most that many cells are filled.

    Holes are the 4-connected background components that do not touch the array's edge, as in
    binary_fill_holes, whose iterated dilation from the edge is 3-4x slower on big rasters.
    A large raster with no hole at all (see _hole_count) is returned as it is (mask itself).
    """
    if mask.size >= _FILL_CHECK_MIN_CELLS and _hole_count(mask) == 0:
        return mask
    lab, n = ndimage.label(~mask)
    outside = np.zeros(n + 1, dtype=bool)
    for edge in (lab[0], lab[-1], lab[:, 0], lab[:, -1]):  # the four edges of the raster
        outside[edge] = True
    if max_cells is not None:
        outside |= np.bincount(lab.ravel(), minlength=n + 1) > max_cells
    outside[0] = False  # label 0 is the mask itself
    return ~outside[lab]


def _hole_count(mask: np.ndarray) -> int:
    """Number of holes of a 2-D bool mask, as _fill_holes counts them: 4-connected background
    components that do not touch the edge.

    By the Euler number of the 8-connected foreground (components minus holes, from the 2 x 2
    windows of the zero-padded mask, Gray 1971): the holes are the bounded background
    components of the padded plane, exactly those that do not touch the edge. Labelling the
    sparse foreground of a wall cluster's footprint costs half as much as labelling its
    background.
    """
    q = np.pad(mask, 1).view(np.uint8)
    a, d = q[:-1, :-1], q[1:, 1:]
    s = a + q[:-1, 1:] + q[1:, :-1] + d  # foreground cells in each 2 x 2 window
    n1 = np.count_nonzero(s == 1)
    n3 = np.count_nonzero(s == 3)
    n_diag = np.count_nonzero((s == 2) & (a == d))  # two cells on a diagonal
    euler = (n1 - n3 - 2 * n_diag) // 4
    _, n_comp = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    return n_comp - euler


def _close3(mask: np.ndarray) -> np.ndarray:
    """``ndimage.binary_closing(mask, np.ones((3, 3)))`` of a 2-D bool mask (outside = empty).

    As separable ORs then ANDs of shifted slices: scipy's closing (or max then min filters)
    costs 5-10x more on the large, nearly empty footprint rasters of wall clusters.
    """
    h, w = mask.shape
    pad = np.zeros((h + 4, w + 4), dtype=bool)
    pad[2:-2, 2:-2] = mask
    dil = pad[:-2] | pad[1:-1] | pad[2:]
    dil = dil[:, :-2] | dil[:, 1:-1] | dil[:, 2:]  # (h + 2, w + 2): one ring beyond the raster
    # The erosion sees the outside as empty (border_value=0), whatever the dilation put there.
    dil[0] = dil[-1] = False
    dil[:, 0] = dil[:, -1] = False
    ero = dil[:-2] & dil[1:-1] & dil[2:]
    return ero[:, :-2] & ero[:, 1:-1] & ero[:, 2:]


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
        return ndimage.distance_transform_edt(mask)
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
