"""Tests on grown surfaces: raised plateaus cut out, and the final tests on each
surface as a whole (size, tilt, seen from above, not an object's top)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from supportnode.geometry.surfaces.groups import _components, _median_by_group
from supportnode.geometry.surfaces.planar import _Planes
from supportnode.geometry.surfaces.result import Surface
from supportnode.geometry.voxels import VoxelGrid
from supportnode.kernels.footprint import fill_holes
from supportnode.kernels.morphology import binary_closing, binary_erosion, binary_opening
from supportnode.params import SurfaceParams

# A raised piece of a surface is an object lying on it only when the surface's main piece
# covers at least this share of the cells around it (a rim around a dip, or a piece at the
# surface's edge, is not surrounded by the rest).
_PLATEAU_MIN_AROUND = 0.5


def _drop_raised_plateaus(
    grid: VoxelGrid,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    tolerance: np.ndarray,
    sv: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    params: SurfaceParams,
) -> int:
    """Take, in place, raised plateaus out of the surfaces; returns the voxels taken out.

    Growth crosses height layers within max_step, so a cutting board or a plate (2 cm high)
    joins the worktop it lies on. Within each surface, the joined pairs of adjacent voxels
    (src, dst: indices into the voxels ``sv``) are cut where either voxel's plane, extended to
    the other's cell centre, misses the other's plane there, or where their heights at their
    centres differ, by more than the step (``plateau_min_step``, at least the surface's point
    tolerance): a warp or a gentle slope predicts its neighbours, a step does not. (On a
    steeper ramp level heights differ from cell to cell, but its pieces do not rise above
    each other.) A piece that is not its surface's largest, rises above the pieces across
    its cuts (both planes' misses, median over the cuts), is small (``plateau_max_area``)
    and is surrounded by the largest piece (``_PLATEAU_MIN_AROUND`` of the cells around it)
    is an object lying on the surface. A dip is lower, a table's rim around a dip is not
    surrounded by it, pieces of a ramp do not rise, pieces of a floor between a lidar's rings
    meet no cut. ``planes`` of the voxels just beside a plateau may change (see below)."""
    if params.plateau_min_step <= 0 or len(src) == 0:
        return 0
    comp = surface_of_voxel[sv]
    keep = comp[src] >= 0  # pairs of a surface that is kept (both ends: one surface)
    src, dst = src[keep], dst[keep]
    step = np.maximum(params.plateau_min_step, tolerance)
    cut, rise_pair = _steps(grid, planes, sv, src, dst, step[comp[src]])
    if not cut.any():
        return 0
    piece = _components(len(sv), src[~cut], dst[~cut])
    n_pieces = int(piece.max()) + 1
    of_piece = np.full(n_pieces, -1, dtype=np.int64)  # surface of each piece (-1: dropped)
    of_piece[piece] = comp
    size = np.bincount(piece, minlength=n_pieces)
    # The main piece of each surface: its largest.
    order = np.lexsort((-size, of_piece))
    first = np.r_[True, of_piece[order][1:] != of_piece[order][:-1]]
    main = np.zeros(n_pieces, dtype=bool)
    main[order[first]] = True
    main &= of_piece >= 0
    # Rise of each piece across its cuts, seen from it (median over its cuts).
    cs, cd = src[cut], dst[cut]
    rise = _median_by_group(np.r_[rise_pair, -rise_pair], np.r_[piece[cs], piece[cd]], n_pieces)
    cand = ~main & (of_piece >= 0) & (rise >= 0.5 * step[np.maximum(of_piece, 0)])
    if not cand.any():
        return 0
    drop = cand & _surrounded(grid, sv, comp, piece, of_piece, main, cand, params)
    if not drop.any():
        return 0
    gone = drop[piece]
    _level_edges(planes, sv, src, dst, cut, gone)
    surface_of_voxel[sv[gone]] = -1
    return int(gone.sum())


def _steps(
    grid: VoxelGrid,
    planes: _Planes,
    sv: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    step: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per joined pair (src, dst into ``sv``): whether a step (``step`` (E,) metres) cuts it,
    and how far src's side rises over dst's (the mean of both planes' misses), metres."""
    # Each voxel's plane as its height h at the cell centre and its slopes (sx, sy).
    nrm, mean = planes.normal[sv], planes.mean[sv]
    sx, sy = -nrm[:, 0] / nrm[:, 2], -nrm[:, 1] / nrm[:, 2]
    kx, ky = grid.keys[sv, 0], grid.keys[sv, 1]
    vx, vy = float(grid.size[0]), float(grid.size[1])
    h = mean[:, 2] + sx * ((kx + 0.5) * vx - mean[:, 0]) + sy * ((ky + 0.5) * vy - mean[:, 1])
    dx, dy = (kx[dst] - kx[src]) * vx, (ky[dst] - ky[src]) * vy
    dh = h[dst] - h[src]
    miss_dst = sx[src] * dx + sy[src] * dy - dh  # src's plane at dst's centre, minus dst's
    miss_src = dh - sx[dst] * dx - sy[dst] * dy  # dst's plane at src's centre, minus src's
    # A level neighbour of a step's voxel sees the step (dh) although the plane fitted across
    # the step, tilted, continues into both sides.
    cut = (np.abs(miss_dst) > step) | (np.abs(miss_src) > step) | (np.abs(dh) > step)
    return cut, 0.5 * (miss_dst[cut] - miss_src[cut])


def _surrounded(
    grid: VoxelGrid,
    sv: np.ndarray,
    comp: np.ndarray,
    piece: np.ndarray,
    of_piece: np.ndarray,
    main: np.ndarray,
    cand: np.ndarray,
    params: SurfaceParams,
) -> np.ndarray:
    """(pieces,) bool: the candidate pieces that are small (``plateau_max_area``) and ringed
    by their surface's main piece (``_PLATEAU_MIN_AROUND`` of the cells around them)."""
    n_pieces = len(of_piece)
    kx, ky = grid.keys[sv, 0], grid.keys[sv, 1]
    vx, vy = float(grid.size[0]), float(grid.size[1])
    # Footprint cells (linear keys on a padded grid) of the candidates and of the main pieces;
    # the share of the cells around a candidate that its surface's main piece covers.
    lo_x, lo_y = int(kx.min()) - 1, int(ky.min()) - 1
    span = int(ky.max()) - lo_y + 2
    ncell = (int(kx.max()) - lo_x + 2) * span
    lin = (kx - lo_x) * span + (ky - lo_y)
    in_cand = cand[piece]
    cand_cells = np.unique(piece[in_cand] * ncell + lin[in_cand])
    c_piece = cand_cells // ncell
    small = np.bincount(c_piece, minlength=n_pieces) * vx * vy <= params.plateau_max_area
    ring8 = np.array([span * i + j for i in (-1, 0, 1) for j in (-1, 0, 1) if i or j])
    ring = np.unique((cand_cells[:, None] + ring8).ravel())
    ring = ring[~np.isin(ring, cand_cells)]
    r_piece = ring // ncell
    main_of = np.zeros(int(comp.max()) + 1, dtype=np.int64)
    main_of[of_piece[main]] = np.flatnonzero(main)
    in_main = main[piece]
    main_cells = np.unique(piece[in_main] * ncell + lin[in_main])
    around = np.isin(main_of[of_piece[r_piece]] * ncell + ring % ncell, main_cells)
    share = np.bincount(r_piece, weights=around, minlength=n_pieces) / np.maximum(
        np.bincount(r_piece, minlength=n_pieces), 1
    )
    return small & (share >= _PLATEAU_MIN_AROUND)


def _level_edges(
    planes: _Planes,
    sv: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    cut: np.ndarray,
    gone: np.ndarray,
) -> None:
    """A voxel across a plateau's edge holds surface and the plateau's rim: its plane, tilted,
    meets the plateau's top. It takes, in place, the plane of its most level neighbour when
    that is more level (as absorbed clutter carries a plane over), so that its surface points
    stay on and the plateau's are left off."""
    nrm = planes.normal[sv]
    a, b = np.r_[src[cut], dst[cut]], np.r_[dst[cut], src[cut]]
    edge = np.zeros(len(sv), dtype=bool)
    edge[a[gone[b] & ~gone[a]]] = True
    a, b = np.r_[src, dst], np.r_[dst, src]
    ok = edge[a] & ~gone[b] & (nrm[b, 2] > nrm[a, 2])
    a, b = a[ok], b[ok]
    if len(a):
        order = np.lexsort((-nrm[b, 2], a))
        a, b = a[order], b[order]
        first = np.r_[True, a[1:] != a[:-1]]
        to, by = sv[a[first]], sv[b[first]]
        planes.mean[to] = planes.mean[by]
        planes.normal[to] = planes.normal[by]


def _drop_unfit(
    grid: VoxelGrid,
    surfaces: list[Surface],
    labels: np.ndarray,
    lut: np.ndarray,
    params: SurfaceParams,
    sensor_origin: np.ndarray | None,
) -> tuple[list[Surface], np.ndarray]:
    """Final tests on each surface as a whole; ids stay in largest-first order.

    labels, lut: the surface id of the grid's points, in its voxel order (``grid.order``),
    is ``lut[labels]``; returns the surfaces kept and the lut to their new ids.
    Size on measured areas and widths (growth could only bound them by whole cells); tilt of
    the plane fitted to all its points (sparse scan lines across a ramp look level voxel by
    voxel); seen from above when the sensor position is known; not the top of an object
    standing on another surface (:func:`_object_tops`)."""
    cos_tilt = np.cos(np.radians(params.max_tilt_deg))
    below = np.inf if sensor_origin is None else float(np.asarray(sensor_origin)[2]) - 0.05
    keep = [
        s
        for s in surfaces
        if s.area >= params.min_area
        and s.width >= params.min_width
        and s.normal[2] >= cos_tilt
        and s.height < below
    ]
    tops = _object_tops(grid, labels, lut, keep, params)
    keep = [s for s, top in zip(keep, tops, strict=True) if not top]
    if len(keep) == len(surfaces):
        return surfaces, lut
    new_id = np.full(len(surfaces) + 1, -1, dtype=np.int64)  # last entry maps -1 to -1
    for i, s in enumerate(keep):
        new_id[s.id] = i
        s.id = i
    return keep, new_id[lut].astype(np.int32)


# An object top is surrounded by its lower surface on at least this share of its outline (a
# box against a wall still shows the worktop on its other sides) ...
_TOP_MIN_AROUND = 0.25
# ... and under its inner footprint that surface shows at most this share of the points it
# has elsewhere per square metre: a solid box hides what it stands on, while the floor under
# a table or a bench is seen at least in part.
_TOP_MAX_SEEN = 0.2
# Points enough to compare those densities (thinned evenly above this).
_TOP_MAX_POINTS = 20_000
# ... unless something stands on it: this many off-surface points over it, in cells where
# nothing rises beyond object_top_max_height, make it a support after all (a cabinet on a desk holding a
# globe is a place to put things; a bare microwave top is not).
_TOP_MIN_LOAD = 30
# ... and only a face at least this high above the surface around it (metres): lower, it is
# a box's top with a box standing on it, two objects (as mOSD labels a stack), not furniture.
_TOP_CARRY_MIN_HEIGHT = 0.2


def _object_tops(
    grid: VoxelGrid,
    labels: np.ndarray,
    lut: np.ndarray,
    surfaces: list[Surface],
    params: SurfaceParams,
) -> np.ndarray:
    """(S,) bool: which surfaces are the tops of objects standing on another surface.

    lut[labels]: (N,) surface ids in the grid's voxel order. A face is an object's top when it is
    small (``object_top_max_area``), low above a surface lying around it
    (``object_top_max_height``), and that surface is not seen under it. A table or a shelf
    board differs in one of these: it is large, or high, or the floor or board below it
    shows under it. One loop iteration per pair of surfaces (a few), vectorised inside."""
    out = np.zeros(len(surfaces), dtype=bool)
    max_area = params.object_top_max_area
    small = [i for i, s in enumerate(surfaces) if s.area < max_area]
    if max_area <= 0 or len(surfaces) < 2 or not small:
        return out
    lin, keys, below = _candidates_below(surfaces, small, params)
    if not below:
        return out
    voxel_cell = lin(grid.keys[:, :2])  # each voxel's column, for _hidden and _load
    out[list(_hidden(grid, labels, lut, surfaces, keys, below, voxel_cell))] = True
    for i in np.flatnonzero(out).tolist():  # a few object tops: do they carry something?
        rise = min(surfaces[i].height - surfaces[j].height for j in below[i])
        out[i] = (
            rise < _TOP_CARRY_MIN_HEIGHT
            or _load(grid, labels, lut, keys[i], voxel_cell, surfaces[i].height, params)
            < _TOP_MIN_LOAD
        )
    return out


def _candidates_below(
    surfaces: list[Surface], small: list[int], params: SurfaceParams
) -> tuple[Callable[[np.ndarray], np.ndarray], list[np.ndarray], dict[int, list[int]]]:
    """For :func:`_object_tops`: the cells' linear key function, each surface's cell keys,
    and for each small face the surfaces lying around it, a little lower, not plainly seen
    under it (faces with none left out)."""
    max_height = params.object_top_max_height
    cells = np.concatenate([s.cells for s in surfaces])
    lo = cells.min(axis=0) - 1
    span = int(cells[:, 1].max() - lo[1]) + 2

    def lin(c: np.ndarray) -> np.ndarray:  # cells (C, 2) -> linear keys on a padded grid
        return (c[:, 0] - lo[0]) * span + (c[:, 1] - lo[1])

    keys = [lin(s.cells) for s in surfaces]  # distinct cells already
    sorted_keys = [np.sort(k) for k in keys]  # membership by binary search (see _within)
    ring8 = np.array([span * dx + dy for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy])
    edge4 = np.array([span, -span, 1, -1])
    below = {}
    for i in small:
        s = surfaces[i]
        ring = np.setdiff1d(keys[i][:, None] + ring8, keys[i])
        inner = keys[i][_within(keys[i][:, None] + edge4, sorted_keys[i]).all(axis=1)]
        under = [
            j
            for j, t in enumerate(surfaces)
            if params.max_step < s.height - t.height <= max_height
            and _within(ring, sorted_keys[j]).mean() >= _TOP_MIN_AROUND
            # Cells are coarse: a box's footprint cells also hold the worktop beside it, but
            # a surface in most of the inner cells is plainly seen under the face.
            and not (len(inner) and _within(inner, sorted_keys[j]).mean() > 0.5)
        ]
        if under:
            below[i] = under
    return lin, keys, below


def _within(x: np.ndarray, sorted_keys: np.ndarray) -> np.ndarray:
    """``np.isin(x, sorted_keys)`` (x's shape) for ascending sorted_keys."""
    pos = np.minimum(np.searchsorted(sorted_keys, x), max(len(sorted_keys) - 1, 0))
    return sorted_keys[pos] == x if len(sorted_keys) else np.zeros(x.shape, bool)


def _hidden(
    grid: VoxelGrid,
    labels: np.ndarray,
    lut: np.ndarray,
    surfaces: list[Surface],
    keys: list[np.ndarray],
    below: dict[int, list[int]],
    voxel_cell: np.ndarray,
) -> list[int]:
    """The faces of ``below`` under whose inner footprint a surface around them shows at
    most _TOP_MAX_SEEN of its usual density (a solid box hides what it stands on)."""
    # Points of these faces and of the surfaces around them, in the faces' columns: xy and
    # surface id, thinned to a bounded number (the test compares densities).
    ids = np.array(
        sorted(
            {surfaces[i].id for i in below} | {surfaces[j].id for b in below.values() for j in b}
        )
    )
    vox = np.flatnonzero(np.isin(voxel_cell, np.concatenate([keys[i] for i in below])))
    n_pts = grid.counts[vox]
    pos = np.repeat(grid.starts[vox] - (np.cumsum(n_pts) - n_pts), n_pts) + np.arange(n_pts.sum())
    sid = lut[labels[pos]]
    pos = pos[np.isin(sid, ids)]
    step = max(1, len(pos) // _TOP_MAX_POINTS)
    pos = pos[::step]
    v = grid.voxel_at(pos)
    xy = (
        np.stack([grid.local[0][pos], grid.local[1][pos]], axis=1)
        + grid.keys[v, :2] * grid.size[:2]
    )
    sid = lut[labels[pos]]
    out = []
    for i, under in below.items():
        s = surfaces[i]
        found, (origin, cell) = _inner_footprint(xy[sid == s.id], s.area)
        if found is None:
            continue  # too small to tell what lies under it: keep
        for j in under:
            t = surfaces[j]
            f = np.floor((xy[sid == t.id] - origin) / cell).astype(np.int64)
            ok = np.all((f >= 0) & (f < found.shape[::-1]), axis=1)
            seen = int(found[f[ok, 1], f[ok, 0]].sum())
            expected = t.point_count / step / max(t.area, 1e-9) * found.sum() * cell**2
            if seen <= _TOP_MAX_SEEN * expected:
                out.append(i)
                break
    return out


def _load(
    grid: VoxelGrid,
    labels: np.ndarray,
    lut: np.ndarray,
    cells: np.ndarray,
    voxel_cell: np.ndarray,
    height: float,
    params: SurfaceParams,
) -> int:
    """Off-surface points over the ``cells`` (linear keys) of a face at ``height``, from
    2 ``point_tolerance`` to ``object_top_max_height`` above it, in cells where nothing rises
    higher (a wall beside the face shares its edge cells and goes on up). voxel_cell: (M,)
    the linear key of each voxel's column, as ``cells``."""
    vox = np.flatnonzero(np.isin(voxel_cell, cells))
    if len(vox) == 0:
        return 0
    n_pts = grid.counts[vox]
    pos = np.repeat(grid.starts[vox] - (np.cumsum(n_pts) - n_pts), n_pts) + np.arange(n_pts.sum())
    v = np.repeat(vox, n_pts)
    z = grid.local[2][pos] + grid.keys[v, 2] * grid.size[2]
    cell = voxel_cell[v]
    tall = np.unique(cell[z > height + params.object_top_max_height])
    above = (z > height + 2 * params.point_tolerance) & (lut[labels[pos]] < 0)
    return int((above & ~np.isin(cell, tall)).sum())


def _inner_footprint(
    xy: np.ndarray, area: float
) -> tuple[np.ndarray | None, tuple[np.ndarray, float]]:
    """Raster of the inside of a face from its (P, 2) points and area: image[iy, ix] on square
    cells of twice the point spacing, with stray lines (a wall's edge picked up at the same
    height) opened away and one cell of margin eroded; None when nothing is left. Returns
    (image, (origin xy, cell))."""
    if len(xy) == 0 or area <= 0:
        return None, (np.zeros(2), 1.0)
    cell = 2.0 * float(np.sqrt(area / len(xy)))
    origin = xy.min(axis=0) - 2 * cell
    f = np.floor((xy - origin) / cell).astype(np.int64)
    img = np.zeros((int(f[:, 1].max()) + 3, int(f[:, 0].max()) + 3), dtype=bool)
    img[f[:, 1], f[:, 0]] = True
    img = binary_erosion(binary_opening(fill_holes(binary_closing(img))))
    return (img if img.any() else None), (origin, cell)
