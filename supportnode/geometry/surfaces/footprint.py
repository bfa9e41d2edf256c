"""Footprints of surfaces on the xy cell grid: widths (inscribed disc) and outlines."""

from __future__ import annotations

import numpy as np

from supportnode.geometry.surfaces.groups import _components
from supportnode.kernels.morphology import distance_transform


def _cells_key(cells: np.ndarray) -> bytes:
    """Hashable identity of (C, 2) distinct cells in ascending (x, y) order."""
    return np.ascontiguousarray(cells, dtype=np.int64).tobytes()


def _unique_cells(cells: np.ndarray, comp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct (component, cell) pairs: returns their cell linear keys and components."""
    if len(cells) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    c = cells - cells.min(axis=0)
    span = int(c[:, 1].max()) + 1
    lin = c[:, 0] * span + c[:, 1]
    ncell = (int(c[:, 0].max()) + 1) * span
    pair = np.unique(comp.astype(np.int64) * ncell + lin)
    return pair % ncell, pair // ncell


def footprint_width(cells: np.ndarray, cell_size: tuple[float, float]) -> float:
    """Width of a 2-D footprint: diameter of the largest inscribed disc, metres.

    cells: (C, 2) int cell coordinates. The raster is upsampled twice so that even widths
    are not rounded down by a whole cell."""
    return float(footprint_widths([cells], cell_size)[0])


def footprint_widths(cells_list: list[np.ndarray], cell_size: tuple[float, float]) -> np.ndarray:
    """:func:`footprint_width` of each of several non-empty footprints, (S,) float64.

    The footprints' rasters are stacked into a few images (:func:`_stacked_rasters`) and take
    one distance transform each: a call costs far more than the pixels of a board. Every
    raster has a zero margin all round, so each pixel's nearest zero lies in its own raster
    and the distances are those of the rasters taken one by one."""
    out = np.zeros(len(cells_list))
    if len(cells_list) == 0:
        return out
    for members, img, first_row in _stacked_rasters(cells_list, upsample=2):
        dist = distance_transform(img)
        out[members] = np.maximum.reduceat(dist.max(axis=1), first_row[:-1])
    return out * min(cell_size)


# Rasters stacked into one image may leave at most this many pixels empty beyond their own
# (a large floor is rasterised apart from the many small boards).
_STACK_SLACK = 1 << 14


def _stacked_rasters(cells_list: list[np.ndarray], upsample: int):
    """Rasters of several non-empty footprints of (C, 2) integer cells, stacked along y into a
    few zero-filled images, each as wide as its widest raster.

    A footprint's raster spans its cells' bounding box and one empty cell all round, from its
    origin cell ``min(cells) - 1``; each cell is ``upsample`` x ``upsample`` pixels. Yields
    ``(members, image, first_row)``: the footprints' indices (int64), the stacked bool
    image[iy, ix], and (len(members) + 1,) the first row of each raster (then the height);
    each raster starts at column 0."""
    count = np.array([len(c) for c in cells_list])
    cells = np.concatenate(cells_list).astype(np.int64, copy=False)
    bounds = np.r_[0, np.cumsum(count)[:-1]]
    origin = np.minimum.reduceat(cells, bounds, axis=0) - 1
    size = (np.maximum.reduceat(cells, bounds, axis=0) - origin + 2) * upsample
    height, width = size[:, 1].tolist(), size[:, 0].tolist()
    # Widest first: a run of rasters of similar width stacks with little waste.
    rank = np.argsort(-size[:, 0], kind="stable")
    owner = np.repeat(np.arange(len(cells_list)), count)
    local = (cells - origin[owner]) * upsample
    start = 0
    while start < len(rank):  # one group per few footprints, each vectorised over cells
        wide, rows, own = width[rank[start]], 0, 0
        stop = start
        while stop < len(rank):
            h, w = height[rank[stop]], width[rank[stop]]
            if stop > start and wide * (rows + h) > 2 * (own + h * w) + _STACK_SLACK:
                break
            rows, own, stop = rows + h, own + h * w, stop + 1
        members = rank[start:stop]
        first_row = np.r_[0, np.cumsum([height[m] for m in members])]
        row_of = np.zeros(len(cells_list), dtype=np.int64)
        row_of[members] = first_row[:-1]
        in_group = np.zeros(len(cells_list), dtype=bool)
        in_group[members] = True
        sel = in_group[owner]
        iy = local[sel, 1] + row_of[owner[sel]]
        ix = local[sel, 0]
        img = np.zeros((int(first_row[-1]), wide), dtype=bool)
        for dy in range(upsample):  # upsample**2 pixels per cell
            for dx in range(upsample):
                img[iy + dy, ix + dx] = True
        yield members, img, first_row
        start = stop


def cells_outline(cells: np.ndarray, cell_size: tuple[float, float]) -> list[np.ndarray]:
    """Boundary rings of a footprint of (C, 2) integer cells, in metres.

    Returns (K, 2) float64 rings without the closing vertex: counter-clockwise rings bound the
    surface, clockwise rings are holes. The largest ring comes first. Cells that touch only at
    a corner give separate rings."""
    return cells_outlines([cells], cell_size)[0]


def cells_outlines(
    cells_list: list[np.ndarray], cell_size: tuple[float, float]
) -> list[list[np.ndarray]]:
    """:func:`cells_outline` of each of several footprints, traced together: the fixed cost
    of the steps (a ms a footprint) is paid once."""
    out: list[list[np.ndarray]] = [[] for _ in cells_list]
    full = [i for i, c in enumerate(cells_list) if len(c)]
    if not full:
        return out
    cells_list = [cells_list[i] for i in full]
    e, owner = _boundary_edges(cells_list)
    nxt = _next_edge(e, owner)
    n = len(e)
    ring = _components(n, np.arange(n), nxt)
    order, root = _walk_order(ring, nxt)
    n_rings = len(root)
    bounds = np.searchsorted(ring[order], np.arange(n_rings + 1))
    v = e[order, :2].astype(np.float64)
    keep = _turns(v, ring[order], bounds)
    origin = np.stack([c.min(axis=0) for c in cells_list]).astype(np.int64) - 1
    v = (v + origin[owner[order]]) * np.asarray(cell_size)
    kept_bounds = np.r_[0, np.cumsum(np.add.reduceat(keep, bounds[:-1]))]
    v = v[keep]
    rings_of: list[list[np.ndarray]] = [[] for _ in cells_list]
    for k, s in enumerate(owner[root].tolist()):  # one entry per ring (outline and holes)
        rings_of[s].append(v[kept_bounds[k] : kept_bounds[k + 1]])
    for i, rings in zip(full, rings_of, strict=True):
        if len(rings) > 1:
            rings.sort(key=lambda r: -abs(_ring_area(r)))
        out[i] = rings
    return out


def _boundary_edges(cells_list: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Directed boundary edges (E, 4: x0 y0 x1 y1) of non-empty footprints, and the footprint
    of each (E,).

    The surface is on an edge's left; vertex coordinates are those of each footprint's own
    raster; the edges are ordered as one footprint's edges alone would be: by footprint, then
    side, then row and column. (np.roll wraps around, onto the empty border of a raster.)"""
    sides = (
        (0, 1, lambda x, y: (x, y, x + 1, y)),  # nothing below: bottom edge
        (1, -1, lambda x, y: (x + 1, y, x + 1, y + 1)),  # nothing right
        (0, -1, lambda x, y: (x + 1, y + 1, x, y + 1)),  # nothing above
        (1, 1, lambda x, y: (x, y + 1, x, y)),  # nothing left
    )
    edges, owners = [], []
    for members, filled, first_row in _stacked_rasters(cells_list, upsample=1):
        for side, (axis, shift, edge) in enumerate(sides):
            jy, ix = np.nonzero(filled & ~np.roll(filled, shift, axis=axis))
            m = np.searchsorted(first_row, jy, side="right") - 1
            edges.append(np.stack(edge(ix, jy - first_row[m]), 1))
            owners.append(members[m] * 4 + side)
    owner = np.concatenate(owners)
    by = np.argsort(owner, kind="stable")
    return np.concatenate(edges)[by], owner[by] // 4


def _walk_order(ring: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edges in walk order, ring after ring, and each ring's first edge (its smallest
    index).

    Walk order without walking: cut each ring after its smallest edge index, then rank every
    edge by its distance to the cut (pointer jumping: log2(E) vectorised rounds)."""
    n = len(nxt)
    n_rings = int(ring.max()) + 1
    root = np.full(n_rings, n, dtype=np.int64)
    np.minimum.at(root, ring, np.arange(n))
    succ = np.where(nxt == root[ring], -1, nxt)
    dist = (succ >= 0).astype(np.int64)
    for _ in range(int(np.ceil(np.log2(n + 1))) + 1):  # list ranking: log2(E) rounds suffice
        if not (succ >= 0).any():
            break
        ok = succ >= 0
        hop = np.maximum(succ, 0)
        dist = dist + np.where(ok, dist[hop], 0)
        succ = np.where(ok, succ[hop], -1)
    return np.lexsort((-dist, ring)), root


def _turns(v: np.ndarray, ring_of: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(E,) bool: the vertices ``v`` (E, 2) where their ring turns (collinear ones dropped).

    The cross product of the edges in and out is exact on integers; every ring at once: its
    previous and next vertex wrap around within it (``bounds``: each ring's first index)."""
    at = np.arange(len(v))
    prev = np.where(at == bounds[ring_of], bounds[ring_of + 1] - 1, at - 1)
    after = np.where(at == bounds[ring_of + 1] - 1, bounds[ring_of], at + 1)
    cross = (v[:, 0] - v[prev, 0]) * (v[after, 1] - v[:, 1]) - (v[:, 1] - v[prev, 1]) * (
        v[after, 0] - v[:, 0]
    )
    return cross != 0


def _next_edge(e: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """Successor of each directed boundary edge (E, 4: x0 y0 x1 y1) of footprint ``owner``
    (E,): the edge of its footprint leaving its end vertex, preferring the left turn so that
    cells touching at a corner make separate rings."""
    span = int(e[:, [1, 3]].max()) + 2  # vertex key (owner, x, y) is unique: y < span ...
    wide = int(e[:, [0, 2]].max()) + 2  # ... and x < wide
    start = (owner * wide + e[:, 0]) * span + e[:, 1]
    end = (owner * wide + e[:, 2]) * span + e[:, 3]
    by_start = np.argsort(start, kind="stable")
    first = np.searchsorted(start[by_start], end)
    count = np.searchsorted(start[by_start], end, side="right") - first
    a = by_start[np.minimum(first, len(e) - 1)]
    b = by_start[np.minimum(first + 1, len(e) - 1)]
    d = e[:, 2:] - e[:, :2]

    def left(j: np.ndarray) -> np.ndarray:  # z of d_i x d_j: +1 left, 0 straight, -1 right
        return d[:, 0] * d[j, 1] - d[:, 1] * d[j, 0]

    return np.where((count > 1) & (left(b) > left(a)), b, a)


def _ring_area(ring: np.ndarray) -> float:
    """Signed shoelace area: positive for counter-clockwise rings."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
