"""Objects as smooth faces joined across convex boundaries (local convexity, after LCCP:
Stein et al., CVPR 2014).

The points on no surface fall in fine cells (:mod:`faces`); cells grow into smooth faces,
and faces meet along boundaries of adjacent cells. Each boundary link votes with the two
faces' own normals on its sides: convex where the normals diverge along the vector between
the cells, concave where they converge by more than the smoothness angle (a bowl's inside
curves gently and stays whole). Faces join across boundaries whose links are mostly not
concave: a box on a box, two boxes face to face, a can against a box come apart at their
creases, while a box's faces, a can's lid and side, stay one. A gap wider than a cell cuts.
Works on unorganised points (a merged map has no image grid). Pure: numpy in, labels out.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.linalg import distances, sym3_eigen_entries
from supportnode.geometry.objects.arrays import ranks
from supportnode.geometry.objects.bridges import split_bridges, split_necks
from supportnode.geometry.objects.clusters import _cluster_voxel
from supportnode.geometry.objects.faces import (
    Cells,
    group_centroids,
    grow_faces,
    make_cells,
    orient,
    window_normals,
)
from supportnode.geometry.objects.floating import join_floating
from supportnode.geometry.objects.stacks import cut_stacks
from supportnode.geometry.objects.votes import CONCAVE_SHARE, absorb_small, vote_segments
from supportnode.geometry.surfaces import Surface
from supportnode.kernels.components import label_edges
from supportnode.kernels.groups import label_boxes, rows_by_key
from supportnode.params import ObjectParams

_MIN_PER_CELL = 3  # median points per occupied cell
_MAX_CELL = 0.04  # metres: the cell stops growing here (gaps of a few cm cut)
_PAD = 3  # cells of padding: windows reach this far
_LINK_CELLS = 1.25  # adjacent cells link when their centroids are this many cells apart at most
# Face growth: a flat window has a surface variation below this; neighbouring cells of one
# face have normals within this angle and lie on each other's plane within this many noise
# sigmas (at least a third of a cell); a face holds at least this many points.
_FLAT = 0.04
_FLAT_NOISE = 2.0  # times a noisy plane's own surface variation
_FACE_DEG = 15.0
_FACE_SIGMAS = 3.0
_FACE_MIN_POINTS = 20
# LCCP's tolerance for noise in the convexity measure (n_a - n_b) . d.
_CONVEX_TOL = 0.05
# The band over a surface that measured no noise (the seed method), metres.
_FALLBACK_BAND = 0.005


def convex_segments(
    points: np.ndarray,
    origin: np.ndarray | None,
    cell: float = 0.005,
    normal_cells: int = 2,
    smooth_deg: float = 25.0,
    min_points: int = 30,
    sigma: float = 0.0015,
    grow: bool = True,
    above: np.ndarray | None = None,
) -> np.ndarray:
    """(M,) int64 segment of each point of ``points`` (M, 3) float, metres; -1 for none.

    origin: (3,) sensor position (normals turn toward it), None: each group of touching
    cells turns its normals away from its centroid. cell: edge of the fine cells (with
    ``grow``, grown x1.5 until a typical occupied cell holds a few points), metres; normal_cells: a cell's normal comes from the cells within this many cells
    of it. smooth_deg: faces whose normals differ by less than this stay joined where they
    meet concavely. min_points: smaller segments join the neighbour they share most links
    with. sigma: the depth noise, metres (faces do not grow across steps above it). above:
    (M,) each point's height above the surface under it (inf over none), metres: with it,
    objects standing on an object's top are cut apart (:mod:`stacks`)."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) == 0:
        return np.zeros(0, np.int64)
    pad = max(_PAD, normal_cells + 1)
    cells = make_cells(pts, cell, pad)
    while grow and np.median(cells.moments[:, 0]) < _MIN_PER_CELL and cell < _MAX_CELL:
        cell *= 1.5
        cells = make_cells(pts, cell, pad)
    # Adjacent cells whose points lie apart by more than a cell and a quarter are not linked:
    # a gap is measured between the points, not between the cells' corners.
    src, dst = cells.grid.adjacent_pairs(cells.centroid, _LINK_CELLS * cell)
    normal, variation = window_normals(cells, normal_cells)
    inside = _inside(cells, src, dst, origin)
    normal = orient(normal, cells.centroid, origin, inside)
    offset = max(_FACE_SIGMAS * sigma, cell / 3.0)
    # A noisy plane's window is not flat to zero: its least eigenvalue is sigma^2 against
    # (2w + 1)^2 cell^2 / 12 in each direction along it.
    width = (2 * normal_cells + 1) * cell
    flat = max(_FLAT, _FLAT_NOISE * sigma**2 / (width**2 / 6.0))
    face = grow_faces(cells, normal, variation, src, dst, flat, _FACE_DEG, offset, _FACE_MIN_POINTS)
    seg = np.full(len(face), -1, np.int64)
    if (face >= 0).any():
        count = cells.moments[:, 0]
        cell_above = None if above is None else np.bincount(cells.of_point, above) / count
        seg, face = _join_faces(
            cells, face, (src, dst), normal_cells, (origin, inside), smooth_deg, cell_above, sigma
        )
        if cell_above is not None:
            up = np.abs(_face_normals(cells, face)[:, 2])
            clearance = max(1.5 * cell, _FACE_SIGMAS * sigma)
            seg = join_floating(cells.centroid, cell_above, face, up, seg, src, dst)
            seg = cut_stacks(
                cells.centroid, count, cell_above, face, up, seg, src, dst, clearance, min_points
            )
        seg = absorb_small(seg, cells.moments[:, 0], src, dst, min_points)
    return seg[cells.of_point]


def _face_normals(cells: Cells, face: np.ndarray) -> np.ndarray:
    """(n_faces, 3) unit normal of the plane fitted to each face's points (sign arbitrary)."""
    on = face >= 0
    n = int(face.max()) + 1
    # Gathered once, not once per moment (np.compress: 4x faster than a mask on rows).
    f_on, m_on = face[on], np.compress(on, cells.moments, axis=0)
    mom = np.stack([np.bincount(f_on, m_on[:, q], n) for q in range(10)], 1)
    count = np.maximum(mom[:, 0], 1.0)
    mean = [mom[:, 1 + a] / count for a in range(3)]
    pairs = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    entries = [mom[:, 4 + q] / count - mean[a] * mean[b] for q, (a, b) in enumerate(pairs)]
    return sym3_eigen_entries(*entries)[1]


def _inside(
    cells: Cells, src: np.ndarray, dst: np.ndarray, origin: np.ndarray | None
) -> np.ndarray | None:
    """Without a sensor, a point inside each cell's object for its normal to turn away
    from: the centroid of its group of touching cells. None with a sensor."""
    if origin is not None:
        return None
    return group_centroids(cells.centroid, label_edges(len(cells.centroid), src, dst))


def _join_faces(
    cells: Cells,
    face: np.ndarray,
    adjacent: tuple[np.ndarray, np.ndarray],
    normal_cells: int,
    sensor: tuple[np.ndarray | None, np.ndarray | None],
    smooth_deg: float,
    cell_above: np.ndarray | None,
    sigma: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(F,) segment of each cell (-1: none): faces joined across their convex boundaries,
    judged with each cell's normal taken from its own face's cells (both sides of a crease
    keep their face's normal, not the blend of the two); and (F,) the faces, necks and
    bridges parted (:mod:`bridges`). adjacent: (src, dst) adjacent cells; sensor: (origin,
    inside) as `orient` takes them; cell_above: (F,) each cell's height above its surface,
    metres, or None; sigma: the depth noise, metres."""
    src, dst = adjacent
    origin, inside = sensor
    up = np.abs(_face_normals(cells, face)[:, 2])
    face, neck = split_necks(cells, face, up, src, dst, origin, cell_above, sigma)
    fa, fb = face[src], face[dst]
    on = (fa >= 0) & (fb >= 0) & (fa != fb)
    s, t = src[on], dst[on]
    # Normals are needed only on the boundaries: their cells' windows, over their own face.
    label = np.where(face >= 0, face, -2 - np.arange(len(face)))
    normal = np.zeros((len(face), 3))
    ends = np.unique(np.concatenate([s, t]))
    part, _ = window_normals(cells, normal_cells, label, ends)
    normal[ends] = orient(
        part,
        np.take(cells.centroid, ends, axis=0),
        origin,
        None if inside is None else np.take(inside, ends, axis=0),
    )
    # Rows gathered once each with np.take (4x faster than fancy indexing of (F, 3) rows).
    d = np.take(cells.centroid, s, axis=0) - np.take(cells.centroid, t, axis=0)
    dist = np.linalg.norm(d, axis=1)
    d /= np.where(dist > 0, dist, 1.0)[:, None]
    n_s, n_t = np.take(normal, s, axis=0), np.take(normal, t, axis=0)
    convexity = np.einsum("ij,ij->i", n_s - n_t, d)
    smooth = np.einsum("ij,ij->i", n_s, n_t) >= np.cos(np.radians(smooth_deg))
    concave = np.zeros(len(src), bool)
    concave[on] = (convexity < -_CONVEX_TOL) & ~smooth
    concave |= on & neck  # across a neck of a level face
    # A face that bridges a crease is parted; the links across the cut are flat (one plane).
    face = split_bridges(face, src, dst, concave, CONCAVE_SHARE)
    fa, fb = face[src], face[dst]
    on = (fa >= 0) & (fb >= 0) & (fa != fb)
    n_face = int(face.max()) + 1
    lo, hi = np.minimum(fa[on], fb[on]), np.maximum(fa[on], fb[on])
    pair, inv = np.unique(lo * n_face + hi, return_inverse=True)
    links = np.bincount(inv.reshape(-1), minlength=len(pair))
    n_concave = np.bincount(inv.reshape(-1), weights=concave[on], minlength=len(pair))
    seg_of_face = vote_segments(n_face, pair // n_face, pair % n_face, links, n_concave)
    return np.where(face >= 0, seg_of_face[np.maximum(face, 0)], -1), face


def cluster_convex(
    cp: np.ndarray,
    surfaces: list[Surface],
    support: np.ndarray,
    params: ObjectParams,
    origin: np.ndarray | None,
    stats: dict,
) -> np.ndarray:
    """(M,) int64 segment of each candidate point cp (M, 3), metres, z up; -1 for none.

    The candidates' connected voxels (:func:`clusters._cluster_voxel`, as the voxel method)
    that are sampled densely enough to show faces (a depth camera's view: a cell of
    ``convex_cell``, 1.5 or 2.25 times it, wide against the points' spacing, and against
    their noise: :func:`quiet_levels`) are segmented by local convexity on cells of that
    size; sparser or noisier ones (a lidar's far returns, a thinly sampled map, a depth
    camera's view at 2 m and beyond) stay whole, to be split by their footprints. In the dense
    ones the points in the noise band of the surface under them (support: (M,) its id, -1
    for none) are the table's and never link two objects: the surface's own band
    (:meth:`Surface.band_width` at the point's range; 1 m when the sensor is unknown)."""
    comp = _cluster_voxel(cp, params.cluster_cell, stats, support)
    voxel = stats.pop("_voxel_of_point", np.zeros(len(cp), np.int64))
    level = cell_levels(cp, comp, voxel, params)
    if (level < len(CELL_STEPS)).any():
        above, band, sigma = _band(cp, support, surfaces, origin)
        noise = _noise(comp, level, sigma)
        level = quiet_levels(level, noise, params.convex_cell)
    dense = level < len(CELL_STEPS)
    stats["dense_components"] = int(dense.sum())
    dense_point = dense[comp]  # gathered once
    stats["_sparse_point"] = ~dense_point  # left whole: for layers.cut_layers
    if not dense.any():
        return comp  # its labels 0..C-1 are all used
    out = np.where(dense_point, -1, comp)
    kept = out >= 0
    out[kept] = ranks(out[kept], len(dense))
    window = _windows(level, noise, params)
    free = dense_point & (above > band)
    stats["band_points"] = int((dense_point & ~free).sum())
    base = int(out.max()) + 1 if (out >= 0).any() else 0
    # One segmentation per cell size and normal window (a few: near and far objects).
    for k, w in sorted(
        {(int(a), int(b)) for a, b in zip(level[dense], window[dense], strict=True)}
    ):
        at = np.flatnonzero(free & (level[comp] == k) & (window[comp] == w))
        if len(at) == 0:
            continue
        seg = convex_segments(
            np.take(cp, at, axis=0),
            origin,
            cell=params.convex_cell * CELL_STEPS[k],
            normal_cells=w,
            smooth_deg=params.convex_smooth_deg,
            min_points=params.min_points,
            sigma=float(np.median(sigma[at])),
            grow=False,
            above=above[at],
        )
        out[at] = np.where(seg >= 0, seg + base, -1)
        base += int(seg.max()) + 1 if len(seg) else 0
    # A dense component that formed no face at all (too small or too curved for its cells)
    # stays whole rather than vanish.
    none = dense & (np.bincount(comp, weights=out >= 0, minlength=len(dense)) == 0)
    if none.any():
        lost = free & none[comp]
        out[lost] = base + ranks(comp[lost], len(dense))
    return out


# The convex cell sizes a component may take (times objects.convex_cell): the first at least
# _CELL_PER_SPACING times its points' spacing (its surfaces stay connected cell to cell, and
# a gap a few spacings wide still cuts), the coarsest only at _CELL_SIGMAS times its noise
# (see quiet_levels); sparser or noisier components are not segmented. Its normals' window spans at least
# _WINDOW_SIGMAS noise sigmas (at most _MAX_WINDOW cells each side).
CELL_STEPS = (1.0, 1.5, 2.25)
_CELL_SIGMAS = 3.0
_CELL_PER_SPACING = 2.5
_WINDOW_SIGMAS = 8.0
_MAX_WINDOW = 5
# The point spacing over cluster_cell / sqrt(points per occupied voxel) (see cell_levels).
_SPACING_PER_VOXEL = 0.75
# Groups wider than this in x or y are room structure, not objects (metres).
_MAX_EXTENT = 1.5


def cell_levels(
    cp: np.ndarray, comp: np.ndarray, voxel: np.ndarray, params: ObjectParams
) -> np.ndarray:
    """Per component (C,): the index in CELL_STEPS of its cell size; len(CELL_STEPS) when
    even the largest is finer than its points' spacing, when it is smaller than
    ``params.min_points`` or wider than room structure (not segmented by convexity).
    cp: (M, 3) points, metres; comp: (M,) their component (-1: none, ignored); voxel: (M,)
    each point's voxel of the clustering grid (``cluster_cell``).

    The spacing comes from the points per occupied voxel (a surface sampled every s metres
    puts about (cluster_cell / s)^2 in one, noise or not: 0.75 of that, measured against
    nearest neighbours on real and simulated depth images)."""
    n = int(comp.max()) + 1 if len(comp) else 0
    level = np.full(n, len(CELL_STEPS), np.int64)
    if n == 0:
        return level
    per_point = np.bincount(voxel)[voxel].astype(np.float64)
    # Points of no component counted in a bin of their own (not masked out: a masked copy of
    # the points cost more than the rest of this function).
    shifted = comp + 1
    size = np.bincount(shifted, minlength=n + 1)[1:]
    per_voxel = np.bincount(shifted, per_point, n + 1)[1:] / np.maximum(size, 1)
    spacing = _SPACING_PER_VOXEL * params.cluster_cell / np.sqrt(np.maximum(per_voxel, 1e-9))
    need = _CELL_PER_SPACING * spacing / params.convex_cell  # in convex cells
    big = (size >= params.min_points) & (need <= CELL_STEPS[-1])
    if not big.any():
        return level
    # Room structure (a wall, a shelf's frame) is no object to part at its creases.
    lo, hi = label_boxes(cp, comp, n)
    big &= (hi - lo)[:, :2].max(axis=1) <= _MAX_EXTENT
    for step_k in reversed(range(len(CELL_STEPS))):
        level[big & (CELL_STEPS[step_k] >= need)] = step_k
    return level


def _noise(comp: np.ndarray, level: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Per component (C,): the median noise of its points (of up to ~200 of them), metres,
    for the components :func:`cell_levels` found dense (0 for the others). sigma: (M,) each
    point's noise (its surface's at its range; 0 when unknown), metres."""
    noise = np.zeros(len(level))
    dense = np.flatnonzero(level < len(CELL_STEPS))
    if len(dense) == 0:
        return noise
    # Rows by component in row order (a stable argsort's), by a counting sort.
    n = len(level)
    order, bounds = rows_by_key(comp, np.arange(n + 1), n)
    for k in dense:
        mine = order[bounds[k] : bounds[k + 1]]
        noise[k] = np.median(sigma[mine[:: max(1, len(mine) // 200)]])
    return noise


def quiet_levels(level: np.ndarray, noise: np.ndarray, convex_cell: float) -> np.ndarray:
    """(C,) the levels of :func:`cell_levels`, those of the coarsest cell dropped (not
    segmented: len(CELL_STEPS)) where the cell is under _CELL_SIGMAS times the component's
    noise (C,), metres.

    Two things thin a depth camera's points: a coarser image (a 320 x 240 camera), which
    keeps them as quiet, and range, which makes them noisier with its square. Cells a few
    spacings wide part the first at its creases; in the second the noise across a cell
    bends the normals more than the creases do, and convexity cuts an object into pieces
    (a desk's far side at 2 m). Nor where no noise was measured (0: no surface under it
    has a depth camera's band): a sampled mesh or a map seen from all sides puts both faces
    of a thin wall (a bowl's) in one such cell. The finer cells are left to the spacing
    alone: a view that dense is near, and its noise is what the faces' growth allows for."""
    out = np.asarray(level).copy()
    last = len(CELL_STEPS) - 1
    cell = convex_cell * CELL_STEPS[last]
    out[(out == last) & ((noise <= 0) | (cell < _CELL_SIGMAS * noise))] = last + 1
    return out


def _windows(level: np.ndarray, noise: np.ndarray, params: ObjectParams) -> np.ndarray:
    """Per component (C,) of :func:`cell_levels`' levels: its normal window in cells, at
    least ``convex_normal_cells``, spanning _WINDOW_SIGMAS of its median noise (C,) metres
    (:func:`_noise`)."""
    low = params.convex_normal_cells
    window = np.full(len(level), low, np.int64)
    if not (level < len(CELL_STEPS)).any():
        return window
    step = np.asarray(CELL_STEPS + (CELL_STEPS[-1],))[level]
    wide = np.ceil(_WINDOW_SIGMAS * noise / (2.0 * params.convex_cell * step)).astype(np.int64)
    return np.clip(wide, low, max(low, _MAX_WINDOW))


def _band(
    pts: np.ndarray, support: np.ndarray, surfaces: list[Surface], origin: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each point's height above the surface under it (inf over none), that surface's band
    half-width and noise sigma at the point's range, metres: three (M,)."""
    by_id = {s.id: s for s in surfaces}
    above = np.full(len(pts), np.inf)
    band = np.zeros(len(pts))
    sigma = np.zeros(len(pts))
    r = np.ones(len(pts)) if origin is None else distances(pts, origin)
    # The surfaces under any point, ascending: counted, not sorted (np.unique's sort).
    for sid in np.flatnonzero(np.bincount(support + 1)[1:]):
        at = np.flatnonzero(support == sid)
        s = by_id[int(sid)]
        above[at] = pts[at, 2] - s.height
        # The noise at range once: the band is that many sigmas (as Surface.band_width).
        sigma[at] = noise = np.hypot(s.noise[0], s.noise[1] * r[at] ** 2)
        band[at] = np.maximum(s.band[0] * noise, s.band[1]) if s.band[1] > 0 else _FALLBACK_BAND
    # The noise is the sensor's: over no surface (a table's edge, a wall's piece), the model
    # of the surface with most points holds at the point's range, as it does over it.
    measured = [s for s in surfaces if s.noise[0] > 0 or s.noise[1] > 0]
    if measured and (support < 0).any():
        a, b = max(measured, key=lambda s: s.point_count).noise
        at = np.flatnonzero(support < 0)
        sigma[at] = np.hypot(a, b * r[at] ** 2)
    return above, band, sigma
