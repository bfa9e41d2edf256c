"""Faces that join two objects, parted before the convexity vote: bridges and necks.

Two cans touching side by side, or two boxes of one height, have coplanar tops that touch:
region growing (:func:`faces.grow_faces`) makes one face of both, that face meets each
object's side convexly, and so joins what the long concave crease between their sides
parts. LCCP (Stein et al., CVPR 2014) has the same blind spot; CPC (Schoeler et al., CVPR
2015) cuts such a face along a plane. Here a face that meets two faces convexly while they
meet each other along a strongly concave boundary is a bridge: each of its cells goes to
the side it is nearer to through the face (the cut runs between them), and the vote
(`votes.vote_segments`) decides on the pooled boundary. A cut across a long face (one object's
L-shaped top) counts its many flat links, and joins again unless the crease outweighs it.

Where an occlusion hides the crease (two cans seen so that one hides their contact, three in
a triangle) their lids still make one level face, and its outline shows where: two discs
touching meet in a neck. A level face whose cells' footprint has a neck (the footprint split
of :mod:`split_footprint`, on the cells' own lattice) is parted there, and the links across
the neck count as concave: one object's necked top is rare, and its sides join it again.
Pure: numpy in, labels out.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.faces import Cells
from supportnode.geometry.objects.split_footprint import split_raster
from supportnode.kernels.components import label_edges
from supportnode.kernels.footprint import fill_holes, label8
from supportnode.kernels.morphology import distance_transform

# A boundary is a crease when it has at least this many links and this share of them concave.
_CREASE_LINKS = 10
_CREASE_SHARE = 0.5
# A face bridges two creased faces when it meets each along at least this many links.
_BRIDGE_LINKS = 5
# A face is level when its normal is within 15 degrees of vertical (the faces' own angle),
# and flat: its cells' heights spread by at most this many cells (standard deviation).
_LEVEL_COS = float(np.cos(np.radians(15.0)))
_FLAT_CELLS = 0.5
# ... or this many noise sigmas, if more (a Kinect's top seen obliquely spreads by its noise).
_FLAT_SIGMAS = 2.0
# Necks of level faces: parts of at least this many cells, a neck shallower than this many
# cells always cut (the footprint split's radius; relative necks as there).
_NECK_MIN_CELLS = 6
_NECK_RADIUS_CELLS = 1.0
# A neck is cut when shallower than this share of both parts' depth: on a lattice of cells
# a third of a lid's radius, two lids touching meet in a neck some 0.6 of their depth (the
# cusp between them fills where it is narrower than a cell); a box's top has no neck at all.
_NECK_RATIO = 0.7
# ... and no neck deeper than this many cells (the cusp between two lids fills a few cells
# at most; a shadow leaves a wide bridge).
_NECK_DEEPEST = 3.0
# ... and each part at least this share of its group's cells (two or three lids touching).
_NECK_MIN_SHARE = 0.2
# A plane's cell is hidden when its ray to the sensor meets a cell within this many cells.
_HIDDEN_CELLS = 40
_HIDDEN_CHUNK = 16_384  # plane cells per pass
# Level groups lower than this above their surface (metres) are not parted: the tops that
# can hold something, as in stacks.py.
_NECK_MIN_HEIGHT = 0.02
# With two bays in its outline at least this share of its deepest cell deep (two discs
# touching: about their radius), a footprint's neck is cut up to this share of its parts'
# depth.
_BAY_SHARE = 0.35
_BAY_NECK_RATIO = 0.9
# Cells this many cells above a level group's height stand on it (their footprint fills its own).
_ABOVE_CELLS = 1.5


def split_necks(
    cells: Cells,
    face: np.ndarray,
    up: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    origin: np.ndarray | None,
    cell_above: np.ndarray | None = None,
    sigma: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(face (F,), cut (L,)): level faces parted at the necks of their footprints, and which
    links cross such a neck. Adjacent level faces at one height (within a cell) are taken
    together: two lids touching are often two faces, joined only by their flat boundary.
    face: (F,) cell labels, -1 none; up: (n_faces,) |z| of each face's unit normal; src,
    dst: (L,) adjacent cells; origin: (3,) the sensor, metres (None: unknown); cell_above:
    (F,) each cell's height above its surface, metres (None: unknown); sigma: the depth
    noise, metres."""
    centroid, size = cells.centroid, cells.size
    n = len(up)
    on = face >= 0
    count = np.maximum(np.bincount(face[on], minlength=n), 1)
    height = np.bincount(face[on], weights=centroid[on, 2], minlength=n) / count
    spread = np.bincount(face[on], weights=centroid[on, 2] ** 2, minlength=n) / count
    # Level and flat: a bowl's inside fits a level plane too, but curves through centimetres.
    flat = np.sqrt(np.maximum(spread - height**2, 0.0)) <= max(
        _FLAT_CELLS * size, _FLAT_SIGMAS * sigma
    )
    level = (up >= _LEVEL_COS) & flat
    fa, fb = face[src], face[dst]
    both = (fa >= 0) & (fb >= 0) & (fa != fb)
    both &= level[np.maximum(fa, 0)] & level[np.maximum(fb, 0)]
    both &= np.abs(height[np.maximum(fa, 0)] - height[np.maximum(fb, 0)]) <= size
    group = label_edges(n, fa[both], fb[both])  # (n,) a label per set of joined level faces
    whole = np.where(on, group[np.maximum(face, 0)], -1)
    big = np.bincount(group, weights=count * level, minlength=n) >= 2 * _NECK_MIN_CELLS
    part = whole.copy()
    fresh = n
    merged = face.copy()
    for g in np.flatnonzero(big).tolist():  # a few level groups per scan
        rows = np.flatnonzero(whole == g)
        if cell_above is not None and np.median(cell_above[rows]) < _NECK_MIN_HEIGHT:
            continue  # a flat thing (a sheet, a mat): no sides to tell its pieces by
        before = fresh
        top = float(np.median(centroid[rows, 2]))
        above = centroid[:, 2] > top + _ABOVE_CELLS * size
        todo = [rows]
        while todo:  # three lids in a row part at one neck, then at the other
            sub = todo.pop()
            cut = _neck_parts(cells, above, sub, top, origin)
            if cut is None or cut.max() < 1 or np.bincount(cut).min() < _NECK_MIN_SHARE * len(rows):
                continue  # a corner behind what stands on the face is no lid of its own
            todo.extend(sub[cut == k] for k in range(int(cut.max()) + 1))
            for k in range(1, int(cut.max()) + 1):
                part[sub[cut == k]] = fresh
                fresh += 1
        if fresh == before:
            # No neck, once what stands on it and what the sensor cannot see are filled in:
            # one top, however few links join its faces (a bottle's shadow across a book
            # leaves a lobe of its top joined to the rest by a link or two).
            merged[rows] = face[rows].min()
    if fresh == n and np.array_equal(merged, face):
        return face, np.zeros(len(src), bool)
    # A face on both sides of a neck becomes one face per side.
    key = np.where(on, merged.astype(np.int64) * (fresh + 1) + part, -1)
    _, relabel = np.unique(key[on], return_inverse=True)
    out = np.full(len(face), -1, np.int64)
    out[on] = relabel.reshape(-1)
    cut_links = (whole[src] >= 0) & (whole[src] == whole[dst]) & (part[src] != part[dst])
    return out, cut_links


def _neck_parts(
    cells: Cells, above: np.ndarray, rows: np.ndarray, top: float, origin: np.ndarray | None
) -> np.ndarray | None:
    """(R,) part of each of the cells ``rows`` (one level group at height ``top``, metres)
    when their x, y footprint on the cell lattice has a neck, else None. above: (F,) bool,
    the cells above the group; origin: (3,) the sensor or None."""
    ijk = cells.grid.ijk
    lo = ijk[rows, :2].min(axis=0)
    ij = ijk[rows, :2] - lo
    hi = ij.max(axis=0)
    occ = np.zeros((int(hi[0]) + 3, int(hi[1]) + 3), bool)  # a one-cell empty border
    occ[ij[:, 0] + 1, ij[:, 1] + 1] = True
    # What stands on the face (a box on a book) notches its visible top without parting it:
    # the cells under it count as footprint.
    over = ijk[above, :2] - lo
    on_top = (over >= 0).all(axis=1) & (over <= hi).all(axis=1)
    occ[over[on_top, 0] + 1, over[on_top, 1] + 1] = True
    u = ij + 0.5  # cell centres, the cell as the raster's unit
    args = (_NECK_RADIUS_CELLS, _NECK_MIN_CELLS, _NECK_RATIO, _NECK_DEEPEST)
    filled = fill_holes(occ)
    cut = split_raster(filled, u[:, 0], u[:, 1], 1.0, *args)
    if cut is None:
        # The cusps between small discs fill on the lattice, so their necks are nearly as
        # deep as the discs; the outline still shows them as deep bays in its convex hull,
        # on both sides of each neck (a box's top has none; an occluded one, one notch):
        # with two, a shallower neck is enough.
        bays, deepest = _bays(filled)
        if (bays >= _BAY_SHARE * deepest).sum() >= 2:
            args = (_NECK_RADIUS_CELLS, _NECK_MIN_CELLS, _BAY_NECK_RATIO, np.inf)
            cut = split_raster(filled, u[:, 0], u[:, 1], 1.0, *args)
    if cut is None or origin is None or not origin[2] > top:
        return cut
    # So does what a taller thing in front hides from the sensor (a bottle's shadow on a
    # book): a neck that closes once the plane's hidden cells are filled is none.
    hidden = _hidden(cells, occ, lo, top, origin)
    if not hidden.any():
        return cut
    return split_raster(fill_holes(occ | hidden), u[:, 0], u[:, 1], 1.0, *args)


def _bays(occ: np.ndarray) -> tuple[np.ndarray, float]:
    """(depths (B,), deepest cell), in cells, of the footprint occ (H, W) bool: how deep each
    bay (a connected set of empty cells inside its convex hull) reaches in from the hull's
    edge, and how far its own cells lie from the footprint's edge."""
    cells = np.argwhere(occ).astype(float)
    if len(cells) < 4 or _collinear(cells):
        return np.zeros(0), 0.0
    # The hull of the cells on the footprint's rim (a cell between its four neighbours lies
    # inside theirs): the same hull, from a fraction of the cells.
    rim = occ.copy()
    rim[1:-1, 1:-1] &= ~(occ[:-2, 1:-1] & occ[2:, 1:-1] & occ[1:-1, :-2] & occ[1:-1, 2:])
    from scipy.spatial import ConvexHull  # here: ~0.18 s to import

    eq = ConvexHull(np.argwhere(rim).astype(float)).equations  # n . x + d <= 0 inside
    empty = np.argwhere(~occ)
    to_edge = -(empty.astype(float) @ eq[:, :2].T + eq[:, 2])
    inside = (to_edge >= -1e-9).all(axis=1)
    bay_cells = np.zeros(occ.shape, bool)
    bay_cells[empty[inside, 0], empty[inside, 1]] = True
    label, n = label8(bay_cells)
    depth = np.zeros(n)
    np.maximum.at(depth, label[bay_cells] - 1, to_edge[inside].min(axis=1))
    return depth, float(distance_transform(occ).max()) - 0.5  # as split_raster


def _collinear(p: np.ndarray) -> bool:
    """Whether the lattice points p (P, 2) (integers as floats) lie on one line: exact, as a
    rank below 2 of ``p - p[0]``."""
    d = p - p[0]
    far = d[np.abs(d).sum(axis=1).argmax()]  # a non-zero direction unless all coincide
    return bool((d[:, 0] * far[1] - d[:, 1] * far[0] == 0).all())


def _hidden(
    cells: Cells, occ: np.ndarray, lo: np.ndarray, top: float, origin: np.ndarray
) -> np.ndarray:
    """(H, W) bool: the empty cells of the raster occ (lattice x, y from lo, a one-cell
    border) whose point on the plane z = top the sensor at origin cannot see: the ray to
    the sensor meets an occupied cell within _HIDDEN_CELLS cells (from two cells up)."""
    grid, size = cells.grid, cells.size
    empty = np.argwhere(~occ)
    ij = empty - 1 + lo
    q = np.column_stack([cells.base[:2] + (ij - grid.pad + 0.5) * size, np.full(len(ij), top)])
    d = origin - q
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    steps = np.arange(2.0, _HIDDEN_CELLS) * size
    dims = grid.dims
    cell_keys = np.sort((grid.ijk[:, 0] * dims[1] + grid.ijk[:, 1]) * dims[2] + grid.ijk[:, 2])
    hit = np.zeros(len(q), bool)
    for a in range(0, len(q), _HIDDEN_CHUNK):  # bounded temporaries on a large footprint
        ray = (
            q[a : a + _HIDDEN_CHUNK, None, :]
            + steps[None, :, None] * d[a : a + _HIDDEN_CHUNK, None]
        )
        at = np.floor((ray - cells.base) / size).astype(np.int64) + grid.pad
        inside = ((at >= 0) & (at < dims)).all(axis=2)
        key = (at[..., 0] * dims[1] + at[..., 1]) * dims[2] + at[..., 2]
        pos = np.minimum(np.searchsorted(cell_keys, key), len(cell_keys) - 1)
        hit[a : a + _HIDDEN_CHUNK] = ((cell_keys[pos] == key) & inside).any(axis=1)
    out = np.zeros(occ.shape, bool)
    out[empty[hit, 0], empty[hit, 1]] = True
    return out


def split_bridges(
    face: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    concave: np.ndarray,
    convex_share: float,
) -> np.ndarray:
    """(F,) face of each cell, bridging faces parted (a part takes a new label; the largest
    keeps the face's own). face: (F,) cell labels, -1 none; src, dst: (L,) adjacent cells;
    concave: (L,) bool, a link between two faces judged concave (False within a face);
    convex_share: a boundary with fewer concave links than this share is convex."""
    fa, fb = face[src], face[dst]
    on = (fa >= 0) & (fb >= 0) & (fa != fb)
    if not on.any():
        return face
    n = int(face.max()) + 1
    lo, hi = np.minimum(fa[on], fb[on]), np.maximum(fa[on], fb[on])
    pair, inv = np.unique(lo * n + hi, return_inverse=True)
    links = np.bincount(inv.reshape(-1), minlength=len(pair))
    n_conc = np.bincount(inv.reshape(-1), weights=concave[on], minlength=len(pair))
    crease = (links >= _CREASE_LINKS) & (n_conc >= _CREASE_SHARE * links)
    if not crease.any():
        return face
    convex = (links >= _BRIDGE_LINKS) & (n_conc < convex_share * links)
    sides = _bridges(pair[crease] // n, pair[crease] % n, pair[convex] // n, pair[convex] % n)
    out = face.copy()
    fresh = n
    for f, faces_ in sides.items():
        fresh = _part(out, f, sorted(faces_), src, dst, fresh)
    return out


def _bridges(ca: np.ndarray, cb: np.ndarray, va: np.ndarray, vb: np.ndarray) -> dict:
    """{face: the faces it bridges}: faces meeting both faces of a crease (ca, cb) convexly
    (convex boundaries va, vb)."""
    near: dict[int, set[int]] = {}
    for a, b in zip(va.tolist(), vb.tolist(), strict=True):
        near.setdefault(a, set()).add(b)
        near.setdefault(b, set()).add(a)
    sides: dict[int, set[int]] = {}
    for a, b in zip(ca.tolist(), cb.tolist(), strict=True):
        for f in near.get(a, set()) & near.get(b, set()):
            sides.setdefault(f, set()).update((a, b))
    return sides


def _part(
    face: np.ndarray, f: int, sides: list[int], src: np.ndarray, dst: np.ndarray, fresh: int
) -> int:
    """Relabel face f's cells in place by the side (of ``sides``) each is nearest to, in
    links through f; returns the next free label."""
    cells = np.flatnonzero(face == f)
    local = np.full(len(face), -1, np.int64)
    local[cells] = np.arange(len(cells))
    inner = (local[src] >= 0) & (local[dst] >= 0)
    m = len(cells) + len(sides)
    # Graph over f's cells plus one node per side, linked to the cells of f it touches.
    a, b = [local[src[inner]]], [local[dst[inner]]]
    for k, s in enumerate(sides):
        for x, y in ((src, dst), (dst, src)):
            touch = (local[x] >= 0) & (face[y] == s)
            a.append(local[x[touch]])
            b.append(np.full(int(touch.sum()), len(cells) + k))
    i, j = np.concatenate(a), np.concatenate(b)
    # Imported here: only a bridge split gets this far; most detects never load csgraph.
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(m, m)).tocsr()
    seeds = np.arange(len(cells), m)
    _, _, nearest = dijkstra(
        graph,
        directed=False,
        indices=seeds,
        unweighted=True,
        min_only=True,
        return_predecessors=True,
    )
    side = nearest[: len(cells)] - len(cells)  # negative where no side reaches (scipy: -9999)
    side = np.where(side >= 0, side, -1)
    counts = np.bincount(side[side >= 0], minlength=len(sides))
    if (counts > 0).sum() < 2:
        return fresh
    keep = int(np.argmax(counts))
    for other in np.flatnonzero(counts).tolist():
        if other != keep:
            face[cells[side == other]] = fresh
            fresh += 1
    return fresh
