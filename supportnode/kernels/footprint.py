"""2-D footprint rasters of the object splits: rasterising, 3 x 3 closing, hole filling.

A room-sized cluster of walls has a footprint raster of ~500 x 400 cells at 1 cm. With numpy
and scipy each step was a pass of its own (a labelling of the whole background for the holes,
nine shifted copies for the closing), ~5 ms a cluster on noisy lidar maps, where noise makes
every wall thick enough to be tried. Here each is one compiled pass (the hole filling a union-find
over the background's row runs), with the same cells as `scipy.ndimage`'s ``binary_closing`` and ``binary_fill_holes``.

Rasters are (H, W) bool, True = occupied; distances and sizes are in cells.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True)
def _close3(mask: np.ndarray) -> np.ndarray:
    # Dilation by the 3 x 3 square, separably (rows then columns), then erosion: a cell stays
    # when its whole 3 x 3 window is dilated, with the outside of the raster empty.
    h, w = mask.shape
    row = np.zeros((h, w), np.bool_)
    for i in range(h):
        for j in range(w):
            if mask[i, j]:
                for jj in range(max(j - 1, 0), min(j + 2, w)):
                    row[i, jj] = True
    dil = np.zeros((h, w), np.bool_)
    for i in range(h):
        for j in range(w):
            if row[i, j]:
                for ii in range(max(i - 1, 0), min(i + 2, h)):
                    dil[ii, j] = True
    out = np.zeros((h, w), np.bool_)
    for i in range(1, h - 1):
        for j in range(1, w - 1):
            keep = True
            for ii in range(i - 1, i + 2):
                for jj in range(j - 1, j + 2):
                    if not dil[ii, jj]:
                        keep = False
                        break
                if not keep:
                    break
            out[i, j] = keep
    return out


@njit(cache=True, nogil=True)
def _find(parent: np.ndarray, a: int) -> int:
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, nogil=True)
def _background_runs(mask: np.ndarray, value: bool) -> tuple[np.ndarray, np.ndarray, int]:
    # Runs of cells equal to value (False: the background) along each row, (row, first
    # column, end column) and the index of each row's first run; a union-find over runs labels
    # the background far faster than over cells: a room's footprint is mostly empty rows of
    # one or two runs.
    h, w = mask.shape
    runs = np.empty((h * ((w + 1) // 2 + 1), 3), np.int64)
    first = np.empty(h + 1, np.int64)
    n = 0
    for i in range(h):
        first[i] = n
        j = 0
        while j < w:
            if mask[i, j] != value:
                j += 1
                continue
            j0 = j
            while j < w and mask[i, j] == value:
                j += 1
            runs[n, 0], runs[n, 1], runs[n, 2] = i, j0, j
            n += 1
    first[h] = n
    return runs, first, n


@njit(cache=True, nogil=True)
def _joined(runs: np.ndarray, first: np.ndarray, h: int, diagonal: int) -> np.ndarray:
    # Union-find parents of the runs (see _background_runs), each run joined to those of the
    # row above that share a column (diagonal 1: or meet it at a corner, 8-connectivity);
    # every root is its component's first run.
    parent = np.arange(first[h])
    for i in range(1, h):
        a, b = first[i - 1], first[i]
        while a < first[i] and b < first[i + 1]:
            if runs[a, 1] < runs[b, 2] + diagonal and runs[b, 1] < runs[a, 2] + diagonal:
                ra, rb = _find(parent, a), _find(parent, b)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
            if runs[a, 2] < runs[b, 2]:
                a += 1
            else:
                b += 1
    return parent


@njit(cache=True, nogil=True)
def _fill_holes(mask: np.ndarray, max_cells: int) -> np.ndarray:
    h, w = mask.shape
    out = mask.copy()
    runs, first, n = _background_runs(mask, False)
    parent = _joined(runs, first, h, 0)  # 4-connected: runs sharing a column
    size = np.zeros(n, np.int64)
    edge = np.zeros(n, np.bool_)
    for r in range(n):
        root = _find(parent, r)
        size[root] += runs[r, 2] - runs[r, 1]
        if runs[r, 0] == 0 or runs[r, 0] == h - 1 or runs[r, 1] == 0 or runs[r, 2] == w:
            edge[root] = True
    for r in range(n):
        root = _find(parent, r)
        # A hole: background that does not reach the raster's edge (and small enough).
        if not edge[root] and (max_cells < 0 or size[root] <= max_cells):
            for j in range(runs[r, 1], runs[r, 2]):  # a loop compiles faster than a fill
                out[runs[r, 0], j] = True
    return out


@njit(cache=True, nogil=True)
def _label8(mask: np.ndarray) -> tuple[np.ndarray, int]:
    # Foreground runs along rows, joined to the runs of the row above that touch them
    # (sharing or diagonally meeting a column); components numbered by their first run, which
    # is raster order: scipy's numbering.
    h, w = mask.shape
    runs, first, n = _background_runs(mask, True)
    parent = _joined(runs, first, h, 1)
    label = np.zeros(n, np.int32)
    count = 0
    out = np.zeros((h, w), np.int32)
    for r in range(n):
        root = _find(parent, r)
        if root == r:
            count += 1
            label[r] = count
        else:
            label[r] = label[root]
        for j in range(runs[r, 1], runs[r, 2]):  # a loop compiles faster than a slice fill
            out[runs[r, 0], j] = label[r]
    return out, count


@njit(cache=True, nogil=True)
def _rasterise(ux: np.ndarray, uy: np.ndarray, h: int, w: int) -> np.ndarray:
    occ = np.zeros((h, w), np.bool_)
    for r in range(ux.shape[0]):
        # Truncation is floor for the coordinates >= 0 given; +1: the empty border.
        occ[int(ux[r]) + 1, int(uy[r]) + 1] = True
    return occ


def label8(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """``ndimage.label(mask, structure=np.ones((3, 3)))`` of an (H, W) bool raster: (H, W)
    int32 labels 1..n of the 8-connected components (0 outside), numbered in raster order of
    their first cell, and n."""
    return _label8(np.ascontiguousarray(mask, dtype=np.bool_))


def close3(mask: np.ndarray) -> np.ndarray:
    """``ndimage.binary_closing(mask, np.ones((3, 3)))`` of an (H, W) bool raster (the outside
    empty, so no edge cell is set)."""
    return _close3(np.ascontiguousarray(mask, dtype=np.bool_))


def fill_holes(mask: np.ndarray, max_cells: int | None = None) -> np.ndarray:
    """``ndimage.binary_fill_holes(mask)`` of an (H, W) bool raster: the 4-connected background
    components that do not touch the raster's edge are set; with ``max_cells``, only those of
    at most that many cells."""
    limit = -1 if max_cells is None else max(int(max_cells), 0)
    return _fill_holes(np.ascontiguousarray(mask, dtype=np.bool_), limit)


def footprint_raster(
    ux: np.ndarray, uy: np.ndarray, shape: tuple[int, int], max_cells: int
) -> np.ndarray:
    """(H, W) = shape bool footprint of points at raster coordinates ux, uy (P,) float64 (in
    cells from the lower corner, >= 0, below shape - 2): each point's cell set (with a one-cell
    empty border), closed by the 3 x 3 square and its holes of at most ``max_cells`` filled."""
    h, w = int(shape[0]), int(shape[1])
    x = np.ascontiguousarray(ux, dtype=np.float64)
    y = np.ascontiguousarray(uy, dtype=np.float64)
    if len(x) and not (x.min() >= 0 and y.min() >= 0 and x.max() < h - 2 and y.max() < w - 2):
        raise ValueError("raster coordinates must lie in [0, shape - 2)")
    occ = _rasterise(x, y, h, w)
    return _fill_holes(occ | _close3(occ), max(int(max_cells), 0))


@warmer
def _warm() -> None:
    footprint_raster(np.array([0.5, 2.5]), np.array([0.5, 1.5]), (6, 5), 4)
    close3(np.zeros((3, 3), bool))
    label8(np.eye(3, dtype=bool))
    fill_holes(np.zeros((3, 3), bool))
