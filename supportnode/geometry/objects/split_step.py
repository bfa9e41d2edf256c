"""Splitting a cluster at a step of its top height: two boxes of different heights face to
face, whose common footprint has no neck.

Points p (P, 3) float64 metres, z up; parts (P,) int64, 0 = the larger. See _split_step.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.arrays import _cells_xy, _col
from supportnode.kernels.components import label_edges
from supportnode.kernels.footprint import close3, fill_holes
from supportnode.kernels.morphology import binary_dilation, binary_erosion, feature_transform

# Splitting at a step of the top height (see _split_step), metres and fractions: raster cell
# = voxel_size; neighbouring cells whose tops differ by at most _STEP_LINK are one plateau;
# two plateaus of >= _STEP_PART_FRACTION of the cells each, _STEP_COVER together, flat to
# _STEP_FLAT, _STEP_MIN apart, with _STEP_RIM_FREE of their rim beside free space, both reaching
# within _STEP_STAND of the cluster's bottom. Only clusters at most _STEP_MAX_EXTENT across
# (objects, not room structure) that fill _STEP_DENSE of their footprint raster are tried.
_STEP_LINK = 0.015
_STEP_PART_FRACTION = 0.3
_STEP_COVER = 0.7
_STEP_FLAT = 0.01
# Plateaus are apart once more than _STEP_LINK: 2 cm steps (boxes of 8 and 10 cm face to face)
# are cut, with a millimetre of margin for the measured medians.
_STEP_MIN = 0.019
_STEP_RIM_FREE = 0.5
_STEP_STAND = 0.02
_STEP_MAX_EXTENT = 1.5
_STEP_DENSE = 0.9
_STEP_DEPTH = 3  # levels of cuts: up to 2**3 boxes in a row


def _split_step(p: np.ndarray, cell: float, min_points: int) -> tuple[np.ndarray | None, bool]:
    """(P,) part 0 or 1 per point of p (P, 3) when its top is two flat levels, else None; and
    whether the cluster's footprint is dense enough to be tried (see below).

    Boxes of different heights standing face to face have one rectangular footprint, no neck;
    only the top height steps. On a raster of cell (the voxel size), cells whose top heights
    differ by at most _STEP_LINK join into plateaus (8-connected). The cluster splits when
    exactly two plateaus each cover _STEP_PART_FRACTION of the occupied cells and together
    _STEP_COVER, are flat (top s.d. <= _STEP_FLAT), differ by >= _STEP_MIN, each border free
    space along _STEP_RIM_FREE of their rim, and both reach down to the cluster's bottom
    (within _STEP_STAND): a toy car's cabin or a stacked box sits on the part below, a box
    beside another stands on the table. Sparsely sampled clusters (occupied cells under
    _STEP_DENSE of the footprint) are not tried. Each part must hold min_points points.
    Known false cut: one object whose side profile is an L (a step stool) looks the same.
    """
    lo = _col(np.minimum, p[:, :2])
    i, j = _cells_xy(p, None, lo, cell, floor=False)  # truncation = floor (>= 0)
    h, w = int(i.max()) + 1, int(j.max()) + 1
    key = i * w + j
    top = np.full(h * w, -np.inf)
    np.maximum.at(top, key, p[:, 2])  # top height of every cell, -inf when empty
    cells = np.flatnonzero(np.isfinite(top))
    if len(cells) < 2:
        return None, False
    grid = top.reshape(h, w)
    # Sparse sampling (a distant scan) leaves empty cells inside the footprint, where neither
    # the levels nor the free space around them can be judged: such clusters are not tried.
    occupied = np.zeros((h + 2, w + 2), dtype=bool)  # np.pad(..., 1), without its overhead
    occupied[1:-1, 1:-1] = np.isfinite(grid)
    solid = fill_holes(close3(occupied))
    if len(cells) < _STEP_DENSE * solid.sum():
        return None, False
    plateau = _plateaus(grid, cells)
    size = np.bincount(plateau)
    big = np.flatnonzero(size >= _STEP_PART_FRACTION * len(cells))
    if len(big) != 2 or size[big].sum() < _STEP_COVER * len(cells):
        return None, True
    tops = [top[cells[plateau == k]] for k in big]
    if abs(float(np.median(tops[0]) - np.median(tops[1]))) < _STEP_MIN:
        return None, True
    if max(float(t.std()) for t in tops) > _STEP_FLAT:
        return None, True
    # Each level must stand beside the other, not on it: most of its rim borders free space
    # (a box beside a box: three of four sides; a stacked box: none).
    if not _beside_free(solid, cells, plateau, big):
        return None, True
    part = _by_level(p, lo, cell, np.array([np.median(t) for t in tops]))
    if part is None:
        return None, True
    part = _by_plateau(part, key, cells, plateau, big, (h, w))
    counts = np.bincount(part, minlength=2)
    if counts.min() < min_points:
        return None, True
    bottom = np.percentile(p[:, 2], 1.0)
    for n in range(2):
        if np.percentile(p[part == n, 2], 2.0) - bottom > _STEP_STAND:
            return None, True  # one level stands on the other, not on the surface
    return (part if counts[0] >= counts[1] else 1 - part), True  # part 0 the larger


def _split_steps(
    p: np.ndarray, cell: float, min_points: int, depth: int = _STEP_DEPTH
) -> tuple[np.ndarray | None, bool]:
    """(P,) parts 0..K-1 of p (P, 3) by _split_step, each part split again up to depth levels
    (three boxes of three heights face to face step twice), or None; and whether p's footprint
    was dense enough to be tried. Part 0 is the larger part of the first cut."""
    part, dense = _split_step(p, cell, min_points)
    if part is None or depth <= 1:
        return part, dense
    out = part.copy()
    next_part = 2
    for k in (0, 1):
        rows = np.flatnonzero(part == k)
        sub, _ = _split_steps(p[rows], cell, min_points, depth - 1)
        if sub is not None:
            out[rows[sub > 0]] = next_part + sub[sub > 0] - 1
            next_part += int(sub.max())
    return out, dense


def _plateaus(grid: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(C,) int plateau of each occupied cell: the 8-connected components of the cells of the
    top-height raster grid (H, W) m (-inf when empty) at flat indices cells (C,) int64, two
    neighbours linked when their tops differ by at most _STEP_LINK."""
    h, w = grid.shape
    vid = np.full((h, w), -1, dtype=np.int64)
    vid.flat[cells] = np.arange(len(cells))
    rows, cols = [], []
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):  # the four forward 8-neighbours
        a = (slice(0, h - di), slice(max(0, -dj), w - max(0, dj)))
        b = (slice(di, h), slice(max(0, dj), w - max(0, -dj)))
        with np.errstate(invalid="ignore"):  # -inf - -inf between empty cells
            link = np.abs(grid[a] - grid[b]) <= _STEP_LINK
        rows.append(vid[a][link])
        cols.append(vid[b][link])
    # Compiled union-find: scipy's numbering, without building a sparse matrix per cluster.
    return label_edges(len(cells), np.concatenate(rows), np.concatenate(cols))


def _beside_free(
    solid: np.ndarray, cells: np.ndarray, plateau: np.ndarray, big: np.ndarray
) -> bool:
    """Whether each of the plateaus big (of plateau (C,), the plateau of each occupied cell at
    flat indices cells of the (H, W) raster) borders free space along _STEP_RIM_FREE of its
    rim. solid: (H + 2, W + 2) bool, the closed, hole-filled footprint with an empty border."""
    h, w = solid.shape[0] - 2, solid.shape[1] - 2
    # Within two cells: a box's edge cells hold its sides' points, lower than its top.
    near_free = binary_dilation(~solid, np.ones((5, 5), dtype=bool))[1:-1, 1:-1]
    for k in big:  # two plateaus
        mine_flat = np.zeros(h * w, dtype=bool)
        mine_flat[cells[plateau == k]] = True
        mine = mine_flat.reshape(h, w)
        rim = mine & ~binary_erosion(mine, np.ones((3, 3), dtype=bool), border_value=False)
        if (rim & near_free).sum() < _STEP_RIM_FREE * rim.sum():
            return False
    return True


def _by_plateau(
    part: np.ndarray,
    key: np.ndarray,
    cells: np.ndarray,
    plateau: np.ndarray,
    big: np.ndarray,
    shape: tuple[int, int],
) -> np.ndarray:
    """(P,) part 0 or 1 of each point: that of its coarse cell (flat index key (P,) on the
    (H, W) = shape raster) when the cell is in one of the two plateaus big (2,) (of plateau
    (C,), per occupied cell cells (C,)) and borders no cell of the other, else ``part`` (P,)
    (by the finer raster, see _by_level). A box's side holds points at every height: in a fine
    cell of its own, without its top, the highest of them may match the other level."""
    h, w = shape
    grid = np.full((h + 2, w + 2), -1, np.int64)  # an empty border: no wrap at the edges
    i, j = np.divmod(cells, w)
    grid[i + 1, j + 1] = np.where(plateau == big[0], 0, np.where(plateau == big[1], 1, -1))
    near = [np.zeros((h, w), bool), np.zeros((h, w), bool)]
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            shifted = grid[1 + di : h + 1 + di, 1 + dj : w + 1 + dj]
            near[0] |= shifted == 0
            near[1] |= shifted == 1
    own = grid[1:-1, 1:-1]
    sure = ((own == 0) & ~near[1]) | ((own == 1) & ~near[0])
    return np.where(sure.ravel()[key], own.ravel()[key], part)


def _by_level(p: np.ndarray, lo: np.ndarray, cell: float, level: np.ndarray) -> np.ndarray | None:
    """(P,) int64 level 0 or 1 of each point of p (P, 3), by the two levels' heights level (2,)
    m; None when no cell matches either. lo: (2,) the footprint's lower corner, cell: metres.

    Points go by a raster three times finer, whose cells take the plateau their top height
    matches (the coarse cells at the step hold both levels), else the nearest such cell.
    """
    fi, fj = _cells_xy(p, None, lo, cell / 3.0, floor=False)
    fh, fw = int(fi.max()) + 1, int(fj.max()) + 1
    fkey = fi * fw + fj
    ftop = np.full(fh * fw, -np.inf)
    np.maximum.at(ftop, fkey, p[:, 2])
    gap = np.abs(ftop[:, None] - level[None, :])  # (cells, 2) m; inf for empty cells
    mark = np.where(gap.min(axis=1) <= _STEP_LINK, np.argmin(gap, axis=1) + 1, 0)
    mark = mark.reshape(fh, fw)
    if not mark.any():
        return None
    ni, nj = feature_transform(mark == 0)
    return mark[ni, nj].ravel()[fkey] - 1
