"""Splitting a cluster where its x, y footprint has a neck: two barrels side by side.

The footprint is rasterised (cell = voxel_size / 3, metres), closed and hole-filled; its depth
map (distance of each cell to the footprint's edge, in cells) is cut at ascending levels until
it falls apart into deep, large parts (see _split_footprint). Points xy (P, 2) float64 metres;
parts (P,) int64, 0 = the largest.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from supportnode.geometry.objects.arrays import _col
from supportnode.geometry.objects.raster import (
    _EDT_SPARSE_MAX_FILL,
    _EDT_SPARSE_MIN_CELLS,
    _edt_inner,
    _taxicab_deep,
    _true_box,
)
from supportnode.kernels.footprint import close3, fill_holes, footprint_raster, label8
from supportnode.kernels.morphology import feature_transform

# A split part must hold at least this fraction of the cluster's footprint cells.
_SPLIT_MIN_FRACTION = 0.15
# A neck this much shallower than both parts it joins is cut (see _split_footprint).
_SPLIT_NECK_RATIO = 0.6
# Points whose cells fill a footprint's notches, (Q, 2) metres, or a function giving them
# (called only when the footprint has a neck), or None.
Fill = np.ndarray | Callable[[], np.ndarray] | None
# Holes up to this area (m^2) are filled before the neck split (a side-scanned barrel is a
# ring); the room that a cluster of walls encloses is not a hole in one object's footprint.
_SPLIT_MAX_HOLE = 1.0


def _may_split(shape: np.ndarray, cell: float, radius: float) -> np.ndarray:
    """(...,) bool: whether a footprint raster of shape (..., 2) cells can hold a split part.

    The raster has an empty border, so no cell is deeper (further from the footprint's edge)
    than half the narrower side, floor((min(shape) - 1) / 2) - 0.5 cells; a part needs a cell
    of depth 1.5 * radius (see _split_footprint). False is exact: such a raster never splits.
    """
    narrow = shape.min(axis=-1)
    deepest = np.floor((narrow - 1) / 2) - 0.5
    return (narrow >= 5) & (deepest * cell >= 1.5 * radius)


def _split_recursive(
    xy: np.ndarray,
    cell: float,
    radius: float,
    min_points: int,
    depth: int,
    fill: Fill = None,
) -> np.ndarray:
    """(P,) part index per point of xy (P, 2): a row of three barrels splits twice. fill:
    (Q, 2) points, metres, whose cells fill the notches of the footprint within xy's box
    (what stands on the cluster, what it hides), or a function giving them (see Fill)."""
    parts = _split_footprint(xy, cell, radius, min_points, fill) if depth > 0 else None
    if parts is None:
        return np.zeros(len(xy), dtype=np.int64)
    out = np.empty(len(xy), dtype=np.int64)
    n = 0
    for k in range(int(parts.max()) + 1):  # two or three parts
        sel = np.flatnonzero(parts == k)
        sub = _split_recursive(np.take(xy, sel, axis=0), cell, radius, min_points, depth - 1, fill)
        out[sel] = sub + n
        n += int(sub.max()) + 1
    return out


def _split_footprint(
    xy: np.ndarray, cell: float, radius: float, min_points: int, fill: Fill = None
) -> np.ndarray | None:
    """Part index per point (P,) when the footprint of xy (P, 2) falls apart, else None.

    The footprint raster's depth map (distance of each cell to the footprint's edge) has one
    peak per convex part and a saddle at each neck between parts. Eroding at level t (opening by
    a disc of radius t) cuts every neck shallower than t. A neck is cut when it is shallower than
    ``radius`` (= split_neck_width / 2, the brief's opening), or than _SPLIT_NECK_RATIO times the
    depth of both parts it joins: rasterising fills the cusp between two touching discs, so their
    neck is never thin in absolute terms, only clearly thinner than the discs themselves.
    Parts must each cover _SPLIT_MIN_FRACTION of the footprint and hold min_points points.
    Every footprint cell then goes to the nearest surviving part (the dilation half of the
    opening, without losing the cells an opening would shave off). The steps are helpers; the
    cheap early exits and the level loop stay here, in the order they save work.
    """
    lo = _col(np.minimum, xy)
    shape = np.floor((_col(np.maximum, xy) - lo) / cell).astype(np.int64) + 3  # = ij.max + 2
    if not _may_split(shape, cell, radius):  # too thin to hold a part deep enough
        return None
    # Raster coordinates, also of the power distances below; column by column, as (xy - lo)
    # would run numpy's inner loop over 2 elements.
    ux = (xy[:, 0] - lo[0]) / cell
    uy = (xy[:, 1] - lo[1]) / cell
    occ = _footprint_raster(ux, uy, shape, cell)
    cut = split_raster(occ, ux, uy, cell, radius, min_points)
    if cut is None or fill is None:
        return cut
    fill_xy = fill() if callable(fill) else fill  # found only for a cluster with a neck
    if len(fill_xy) == 0:
        return cut
    # A neck that closes once what stands on the cluster is filled in is none (a box on a
    # book); the fill only vetoes a cut (a thicker footprint can hold parts of its own).
    filled = _fill_notches(occ, fill_xy, lo, shape, cell)
    return None if split_raster(filled, ux, uy, cell, radius, min_points) is None else cut


def _fill_notches(
    occ: np.ndarray, fill: np.ndarray, lo: np.ndarray, shape: np.ndarray, cell: float
) -> np.ndarray:
    """The footprint occ (H, W) with the cells under the points fill (Q, 2), metres, set
    where they lie between footprint cells along their row or column: what stands on the
    cluster (a box on a book) notches its visible top without parting it, but does not widen
    it."""
    hi = lo + (shape - 3) * cell
    fx, fy = fill[:, 0], fill[:, 1]
    inside = (fx >= lo[0]) & (fx <= hi[0]) & (fy >= lo[1]) & (fy <= hi[1])
    under = np.zeros(occ.shape, bool)
    under[
        ((fx[inside] - lo[0]) / cell).astype(np.int64) + 1,
        ((fy[inside] - lo[1]) / cell).astype(np.int64) + 1,
    ] = True
    between = np.zeros(occ.shape, bool)
    for axis in (0, 1):
        before = np.logical_or.accumulate(occ, axis=axis)
        after = np.flip(np.logical_or.accumulate(np.flip(occ, axis), axis=axis), axis)
        between |= before & after
    return fill_holes(occ | (close3(under) & between), int(_SPLIT_MAX_HOLE / cell**2))


def split_raster(
    occ: np.ndarray,
    ux: np.ndarray,
    uy: np.ndarray,
    cell: float,
    radius: float,
    min_points: int,
    ratio: float = _SPLIT_NECK_RATIO,
    deepest: float = np.inf,
) -> np.ndarray | None:
    """`_split_footprint` on its footprint raster occ (H, W) bool (an empty border), the
    points at raster coordinates ux, uy (P,) (cells from the raster's corner): part index per
    point (P,), or None when the footprint has no neck (one shallower than ``radius`` or than
    ``ratio`` times both parts' depth; none deeper than ``deepest`` cells is cut)."""
    # The taxicab distance to the edge bounds the Euclidean one from above and costs a tenth:
    # a footprint with no cell deep enough for a part (a ring of walls) stops here.
    if not _taxicab_deep(occ, cell, 1.5 * radius):
        return None
    n_cells = int(np.count_nonzero(occ))
    depth = _edt_inner(occ, n_cells) - 0.5  # cell centre to footprint edge, cells
    depth[~occ] = 0.0
    top = float(depth.max())
    if top * cell < 1.5 * radius:
        return None  # no part's peak (<= top) can be deep enough at any level of the loop
    # Every level's set (depth > t >= 0.5) lies in the box of the cells deeper than 0.5: the
    # labelling runs there (the same labels: a box keeps the raster order of its cells), not
    # on the whole raster of a room-sized cluster of walls.
    box = _true_box(depth > 0.5)
    depth_box = depth[box]
    levels = [t for t in _levels(top, cell, radius, ratio) if t <= deepest]
    first, probed = _first_level(depth_box, levels, cell, radius)
    for k in range(first, len(levels)):
        t = levels[k]
        if k in probed:
            comp_box, n = probed[k]
        else:
            comp_box, n = label8(depth_box > t)
        if n < 2:
            continue
        inside = comp_box > 0
        peak = np.zeros(n)
        np.maximum.at(peak, comp_box[inside] - 1, depth_box[inside])
        # A part must itself be thicker than the neck that cuts it off: a wall's or a rail's
        # footprint is all neck and stays whole.
        deep = ((t * cell < radius) | (t <= ratio * peak)) & (peak * cell >= 1.5 * radius)
        if deep.sum() < 2:
            continue
        comp = np.zeros(occ.shape, dtype=comp_box.dtype)
        comp[box] = comp_box
        big = _big_parts(occ, n_cells, comp, deep)
        if big.sum() < 2:
            continue
        part = _power_parts(ux, uy, depth, comp, inside, box, peak, big)
        counts = np.bincount(part, minlength=int(big.sum()))
        if (counts < min_points).any():
            return None
        # Number parts by size so the split does not depend on raster order.
        rank = np.empty(len(counts), dtype=np.int64)
        rank[np.argsort(-counts, kind="stable")] = np.arange(len(counts))
        return rank[part]
    return None


def _footprint_raster(ux: np.ndarray, uy: np.ndarray, shape: np.ndarray, cell: float) -> np.ndarray:
    """(H, W) = shape bool footprint of the points at raster coordinates ux, uy (P,) (in cells
    from the lower corner; an empty border is added), closed and its holes of up to
    _SPLIT_MAX_HOLE m^2 filled; cell in metres."""
    # Closing bridges the gaps between sample points (a 2 cm lattice on the 1 cm raster).
    # Filling holes makes a side-scanned barrel a disc, not a ring that erosion would wipe out,
    # and removes the speckle of sparse, noisy sampling that would fake saddles. (It also fills
    # the small gap between three barrels touching in a triangle, which then stay one object.)
    h, w = int(shape[0]), int(shape[1])
    return footprint_raster(ux, uy, (h, w), int(_SPLIT_MAX_HOLE / cell**2))


def _levels(top: float, cell: float, radius: float, ratio: float) -> list[float]:
    """The ascending depth levels (cells) at which _split_footprint cuts a footprint whose
    deepest cell is top cells deep: the shallowest neck is cut first; at most ~40 levels for
    big footprints."""
    levels = []
    for t in np.arange(0.5, top, max(0.5, top / 40.0)):
        if t * cell >= radius and t > ratio * top:
            break  # no part can be deep enough for this level or any higher (see `deep` there)
        levels.append(t)
    return levels


def _power_parts(
    ux: np.ndarray,
    uy: np.ndarray,
    depth: np.ndarray,
    comp: np.ndarray,
    inside: np.ndarray,
    box: tuple[slice, slice],
    peak: np.ndarray,
    big: np.ndarray,
) -> np.ndarray:
    """(P,) index of the part of each point (raster coordinates ux, uy (P,)) among the big (n,)
    bool parts of comp (H, W) (labels 1..n; inside: comp > 0 within box; peak (n,): each
    part's greatest depth of depth (H, W), cells).

    Each point goes to the part of least power distance |p - c|^2 - rho^2, with c, rho the
    centre and depth of the part's deepest cells (its inscribed disc): for two touching discs
    the cut is then exactly the tangent at the contact, wherever the raster put the neck. (A
    cut one cell off moves the many wall points crowding there.)
    """
    keep = np.flatnonzero(big) + 1
    rho = peak[keep - 1]
    ci, cj = np.nonzero(inside)
    ci += box[0].start  # raster indices, as np.nonzero(comp > 0) gives them
    cj += box[1].start
    lab_c = comp[ci, cj]
    top_cells = depth[ci, cj] >= rho[np.searchsorted(keep, lab_c).clip(0, len(keep) - 1)] - 1
    top_cells &= np.isin(lab_c, keep)
    k_of = np.searchsorted(keep, lab_c[top_cells])
    cnt = np.bincount(k_of, minlength=len(keep))
    centre = np.stack(
        [
            np.bincount(k_of, ci[top_cells], minlength=len(keep)) / cnt,
            np.bincount(k_of, cj[top_cells], minlength=len(keep)) / cnt,
        ],
        axis=1,
    )
    vx, vy = ux + 0.5, uy + 0.5  # cell i's centre is at coordinate i
    # (K, P), row by row: the same sums dx^2 + dy^2 as summing a (K, P, 2) array over its
    # last axis, without that array and its strided reduction.
    dist = np.stack(
        [
            (vx - ck[0]) ** 2 + (vy - ck[1]) ** 2 - rk2
            for ck, rk2 in zip(centre, rho**2, strict=True)
        ]
    )
    return np.argmin(dist, axis=0)


def _first_level(
    depth: np.ndarray, levels: list[float], cell: float, radius: float
) -> tuple[int, dict[int, tuple[np.ndarray, int]]]:
    """The index of the first of the ascending levels at which _split_footprint's loop may find
    two deep parts, and the labellings (labels, count) it made, by level index.

    A deep part holds a cell of depth (H, W) >= 1.5 * radius / cell (the set K). At a level t
    below K's shallowest cell, K lies inside the set labelled (depth > t); if K lies in one of
    its components there, it does at every lower level too (their sets hold this one), so those
    levels have at most one deep part. The test labels the highest such level once: a ring of
    noisy walls has a dozen pieces of K, all joined along the wall, and 4-6 levels labelled on
    a room-sized raster are saved. When K is split there, the labels are reused by the loop.
    """
    deep = depth * cell >= 1.5 * radius
    kmin = float(depth[deep].min())
    below = [k for k, t in enumerate(levels) if t < kmin]
    if len(below) < 2:
        return 0, {}
    k = below[-1]
    comp, n = label8(depth > levels[k])
    on_k = comp[deep]
    if n < 2 or (on_k == on_k[0]).all():
        return k + 1, {}
    return 0, {k: (comp, n)}


def _big_parts(occ: np.ndarray, n_cells: int, comp: np.ndarray, deep: np.ndarray) -> np.ndarray:
    """(n,) bool: the deep parts (deep (n,), parts labelled 1..n in comp (H, W)) whose area, the
    cells of the footprint occ (H, W) (n_cells of them) nearest to the part, is at least
    _SPLIT_MIN_FRACTION of the footprint.

    A cell equidistant from two parts goes to either, as scipy's feature transform picks. On a
    big, sparse raster (a ring of walls: a 500 x 400 raster, 1-5k footprint cells) the
    transform of the whole raster costs 8-12 ms. There, each footprint cell's squared distance
    to every deep part comes from a k-d tree of the part's cells (exact on integer cells), and
    the areas counting tied cells for no part and for every part bound the true ones; when
    both bounds agree on every part, that is the answer, else the transform decides.
    """
    n = len(deep)
    if occ.size >= _EDT_SPARSE_MIN_CELLS and n_cells <= _EDT_SPARSE_MAX_FILL * occ.size:
        ci, cj = np.divmod(np.flatnonzero(occ), occ.shape[1])
        lab = comp[ci, cj]  # 0 outside the level's set
        parts = np.flatnonzero(deep) + 1
        is_part = deep[np.maximum(lab - 1, 0)] & (lab > 0)
        # A part's own cells are at distance 0 from it only: they count for it alone.
        own = np.bincount(lab[is_part], minlength=n + 1)[parts]
        qi, qj = ci[~is_part], cj[~is_part]
        query = np.column_stack([qi, qj]).astype(np.float64)
        d2 = np.empty((len(parts), len(qi)), dtype=np.int64)
        for k, p in enumerate(parts):  # a few parts
            sel = lab == p
            pi, pj = ci[sel], cj[sel]
            from scipy.spatial import cKDTree  # here: ~0.18 s to import

            tree = cKDTree(np.column_stack([pi, pj]).astype(np.float64))
            _, near = tree.query(query)
            d2[k] = (qi - pi[near]) ** 2 + (qj - pj[near]) ** 2
        tied = d2 == d2.min(axis=0)
        alone = tied.sum(axis=0) == 1
        low = own + tied[:, alone].sum(axis=1)
        high = low + tied[:, ~alone].sum(axis=1)
        need = _SPLIT_MIN_FRACTION * n_cells
        if ((low >= need) == (high >= need)).all():
            big = np.zeros(n, dtype=bool)
            big[parts - 1] = low >= need
            return big
    markers = np.where(deep[np.maximum(comp - 1, 0)] & (comp > 0), comp, 0)
    ni, nj = feature_transform(markers == 0)
    owner = markers[ni, nj]  # nearest part of every cell
    area = np.bincount(owner[occ], minlength=n + 1)[1:]
    return deep & (area >= _SPLIT_MIN_FRACTION * n_cells)
