"""Free space: the part of each support surface not under an object, and its largest free disc.

A fine 2-D grid (``FreeSpaceParams.cell_size``) covers the surface's footprint cells (coarse grid
``Surface.cell_size``). Cells under the objects standing on the surface, dilated by ``margin``,
are occupied; the rest of the surface is free. The largest free disc (where a robot can put
something round, or land) is the maximum of the distance transform of the free mask.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from supportnode.geometry.objects import Cluster, ObjectResult, Segmentation
from supportnode.geometry.surfaces import Surface, SurfaceResult
from supportnode.kernels.morphology import distance_transform, squared_distance_transform
from supportnode.params import FreeSpaceParams

__all__ = ["FreeSpace", "free_space", "free_space_all"]

# Margins of up to this many cells are dilated by shifted slices (see _dilate_margin).
_DILATE_MAX_REACH = 16


@dataclass
class FreeSpace:
    """Free part of one surface. Lengths in metres, areas in m^2."""

    surface_id: int
    free_area: float  # surface not under an object footprint dilated by margin
    occupied_area: float  # surface under the dilated footprints
    disc_center: np.ndarray  # (2,) x, y of the largest free disc (nan when nothing is free)
    disc_radius: float  # 0 when nothing is free
    grid_origin: np.ndarray  # (2,) x, y of the corner of cell (0, 0)
    cell_size: float
    free_mask: np.ndarray  # (H, W) bool, row = y index, column = x index

    def to_dict(self) -> dict:
        """JSON-ready dictionary, without the mask (that is for pictures and topics)."""
        centre = [None if np.isnan(v) else float(v) for v in self.disc_center]
        return {
            "surface_id": int(self.surface_id),
            "free_area": float(self.free_area),
            "occupied_area": float(self.occupied_area),
            "disc_center": centre,
            "disc_radius": float(self.disc_radius),
            "grid_origin": [float(v) for v in self.grid_origin],
            "cell_size": float(self.cell_size),
            "grid_shape": [int(v) for v in self.free_mask.shape],
        }


def free_space(
    surface: Surface,
    clusters: Sequence[Cluster],
    object_points: Sequence[np.ndarray] | None,
    params: FreeSpaceParams | None = None,
) -> FreeSpace:
    """Free area and largest free disc of one surface.

    clusters: the objects to keep clear of (those whose ``surface_id`` is not this surface's are
    ignored). object_points: for each cluster, its points (P_i, 3) or (P_i, 2), metres; their
    x, y cells are occupied. When None, each cluster's convex footprint polygon is filled instead.
    The surface's footprint includes the cells under its objects (they hold no surface points).
    """
    params = params or FreeSpaceParams()
    on_this = [i for i, cl in enumerate(clusters) if cl.surface_id == surface.id]
    footprints = [np.asarray(clusters[i].footprint, np.float64).reshape(-1, 2) for i in on_this]
    if object_points is None:
        object_xy = None
        extents = [(fp.min(axis=0), fp.max(axis=0)) for fp in footprints if len(fp)]
    else:
        object_xy = [np.asarray(object_points[i], dtype=np.float64)[:, :2] for i in on_this]
        extents = [(xy.min(axis=0), xy.max(axis=0)) for xy in object_xy if len(xy)]
    return _free_space(surface, extents, object_xy, footprints, params)


def _free_space(
    surface: Surface,
    extents: list[tuple[np.ndarray, np.ndarray]],
    object_xy: list[np.ndarray] | None,
    footprints: list[np.ndarray] | None,
    params: FreeSpaceParams,
) -> FreeSpace:
    """:func:`free_space` of the surface given its objects: extents, the x, y box (lo (2,),
    hi (2,)) of each; object_xy, their points' x, y coordinates, a list of (P_i, >= 2) float64
    arrays, metres, whose cells are occupied (how the points are grouped does not matter), or
    None to fill footprints, their (K_i, 2) convex footprints."""
    c = float(params.cell_size)
    cell_size = (float(surface.cell_size[0]), float(surface.cell_size[1]))
    cells = np.asarray(surface.cells, dtype=np.int64).reshape(-1, 2)
    frame = _raster_frame(cells, cell_size, extents, c)
    if frame is None:
        return _empty(surface.id, c)
    origin, w, h = frame
    surf = _surface_raster(cells, cell_size, origin, c, (h, w))
    objects = _object_raster(object_xy, footprints, origin, c, (h, w))
    # The table is under its objects even where it has no points (occluded by them).
    surf |= objects
    surf[0, :] = surf[-1, :] = surf[:, 0] = surf[:, -1] = False  # the blocked border

    if objects.any():
        # Dilation by margin: distance from each cell centre to the nearest object cell centre.
        occupied = _dilate_margin(objects, c, params.margin)
    else:
        occupied = objects
    occupied &= surf
    free = surf & ~occupied
    centre, radius = _largest_disc(free, origin, c)
    # The raster counts border cells whole; the surface's measured area does not. Share that
    # area out in the raster's proportions so that free + occupied == area.
    n_surf = max(int(surf.sum()), 1)
    return FreeSpace(
        surface_id=int(surface.id),
        free_area=float(surface.area) * float(free.sum()) / n_surf,
        occupied_area=float(surface.area) * float(occupied.sum()) / n_surf,
        disc_center=centre,
        disc_radius=radius,
        grid_origin=origin,
        cell_size=c,
        free_mask=free,
    )


def _raster_frame(
    cells: np.ndarray,
    cell_size: tuple[float, float],
    extents: list[tuple[np.ndarray, np.ndarray]],
    c: float,
) -> tuple[np.ndarray, int, int] | None:
    """The raster's origin (2,) m and width, height in cells of ``c`` m, or None when empty.

    It spans the footprint cells and the objects on them, plus one blocked cell all round so
    the distance transform sees the surface's edge as blocked."""
    vx, vy = cell_size
    lo_parts, hi_parts = [], []
    if len(cells):
        lo_parts.append(cells.min(axis=0) * [vx, vy])
        hi_parts.append((cells.max(axis=0) + 1) * [vx, vy])
    for lo_xy, hi_xy in extents:
        lo_parts.append(lo_xy)
        hi_parts.append(hi_xy)
    if not lo_parts:
        return None
    lo = np.min(lo_parts, axis=0)
    hi = np.max(hi_parts, axis=0)
    origin = np.floor(lo / c) * c - c
    w, h = (np.ceil((hi - origin) / c).astype(np.int64) + 1).tolist()
    return origin, w, h


def _surface_raster(
    cells: np.ndarray,
    cell_size: tuple[float, float],
    origin: np.ndarray,
    c: float,
    shape: tuple[int, int],
) -> np.ndarray:
    """(h, w) bool: the fine cells whose centres lie in the surface's coarse footprint cells.

    Looked up 1-D per axis, then by an outer index, so there is no per-cell loop."""
    vx, vy = cell_size
    h, w = shape
    xc = origin[0] + (np.arange(w) + 0.5) * c
    yc = origin[1] + (np.arange(h) + 0.5) * c
    surf = np.zeros((h, w), dtype=bool)
    if len(cells):
        c0 = cells.min(axis=0)
        coarse = np.zeros(tuple(cells.max(axis=0) - c0 + 1), dtype=bool)
        coarse[cells[:, 0] - c0[0], cells[:, 1] - c0[1]] = True
        ix = np.floor(xc / vx).astype(np.int64) - c0[0]
        iy = np.floor(yc / vy).astype(np.int64) - c0[1]
        # The fine cells inside the coarse extent: one run per axis (ix, iy never decrease).
        xs = np.flatnonzero((ix >= 0) & (ix < coarse.shape[0]))
        ys = np.flatnonzero((iy >= 0) & (iy < coarse.shape[1]))
        if len(xs) and len(ys):
            sub = coarse.take(ix[xs], axis=0).take(iy[ys], axis=1).T  # (rows y, cols x)
            surf[ys[0] : ys[-1] + 1, xs[0] : xs[-1] + 1] = sub
    return surf


def _object_raster(
    object_xy: list[np.ndarray] | None,
    footprints: list[np.ndarray] | None,
    origin: np.ndarray,
    c: float,
    shape: tuple[int, int],
) -> np.ndarray:
    """(h, w) bool: the cells of the objects' points, or of their filled convex footprints."""
    h, w = shape
    objects = np.zeros((h, w), dtype=bool)
    if object_xy is not None:
        for xy in object_xy:  # one iteration per group of points
            col = np.floor((xy[:, 0] - origin[0]) / c).astype(np.int64)
            row = np.floor((xy[:, 1] - origin[1]) / c).astype(np.int64)
            objects[row.clip(0, h - 1), col.clip(0, w - 1)] = True
    else:
        for fp in footprints or []:  # one iteration per object
            _fill_convex(objects, fp, origin, c)
    return objects


def _largest_disc(free: np.ndarray, origin: np.ndarray, c: float) -> tuple[np.ndarray, float]:
    """Centre (2,) m and radius m of the largest disc within the free cells (NaN, 0: none).

    The transform runs on the box of the free cells and one cell around: every cell outside it
    is blocked, and for a cell inside, the blocked cell on that ring straight towards any
    blocked cell outside is no further. The same distances, on a smaller raster."""
    if not free.any():
        return np.full(2, np.nan), 0.0
    r0, r1, c0, c1 = _box(free)
    d2 = _squared_edt(free[r0 - 1 : r1 + 1, c0 - 1 : c1 + 1])
    top = d2.max()
    best = np.sqrt(np.float64(top))  # the transform's maximum, as it computes it
    rows, cols = np.nonzero(d2 == top)
    rows += r0 - 1  # raster indices, row-major as np.nonzero over the whole raster
    cols += c0 - 1
    # Of the equally good cells (e.g. the 2x2 centre of an even square), the one nearest
    # their mean: centred, and still a free cell.
    k = int(np.argmin((rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2))
    centre = origin + (np.array([cols[k], rows[k]]) + 0.5) * c
    radius = max(0.0, (float(best) - 0.5) * c)  # to the blocked cell's edge, not its centre
    return centre, radius


def free_space_all(
    surfaces: SurfaceResult,
    objects: ObjectResult | Segmentation,
    points: np.ndarray,
    params: FreeSpaceParams | None = None,
) -> list[FreeSpace]:
    """Free space of every surface, in surface order.

    objects: the objects found on the surfaces, described or only segmented (free space needs
    only which points belong to which object and where it stands). points: (N, 3) float,
    metres, the cloud that ``objects.labels`` (N,) labels.
    """
    params = params or FreeSpaceParams()
    pts = np.asarray(points)
    lab = np.asarray(objects.labels)
    if isinstance(objects, Segmentation):
        sids = [int(v) for v in objects.surface_ids]
        box_lo, box_hi = objects.bbox_min[:, :2], objects.bbox_max[:, :2]
    else:
        sids = [-1 if cl.surface_id is None else int(cl.surface_id) for cl in objects.clusters]
        box_lo = np.array([cl.bbox_min[:2] for cl in objects.clusters]).reshape(-1, 2)
        box_hi = np.array([cl.bbox_max[:2] for cl in objects.clusters]).reshape(-1, 2)
    surfs = surfaces.surfaces
    # The points of all clusters standing on each surface, in one run per surface (what
    # free_space does with the clusters' points, their occupied cells, does not depend on the
    # grouping): one gather of the points on surfaces, not a sort and gather of all clusters.
    slot = {s.id: k for k, s in reversed(list(enumerate(surfs)))}  # first surface of an id
    of_cluster = np.array([slot.get(s, len(surfs)) for s in sids] + [len(surfs)], dtype=np.int32)
    # Only the points of objects on a surface, grouped by surface (labels -1 read the last
    # entry): the same runs, in the same order, as a stable sort of all points' keys, by a
    # counting sort (compiled) without the (N,) keys.
    from supportnode.kernels.groups import rows_by_key  # numba only when used

    order, bounds = rows_by_key(lab, of_cluster, len(surfs))
    out = []
    for s in surfs:  # one iteration per surface
        on_this = [i for i, sid in enumerate(sids) if sid == s.id]
        extents = [(box_lo[i], box_hi[i]) for i in on_this]
        j = slot[s.id]  # its own index, unless an earlier surface has the same id
        rows = order[bounds[j] : bounds[j + 1]]
        xy = np.take(pts, rows, axis=0).astype(np.float64, copy=False)[:, :2]
        out.append(_free_space(s, extents, [xy], None, params))
    return out


def _squared_edt(mask: np.ndarray) -> np.ndarray:
    """Squared ``ndimage.distance_transform_edt`` of a 2-D bool mask with some False cell,
    (H, W) int64 (cells^2): exact integers, without the float64 passes of the distances (the
    square root keeps their order and equality)."""
    return squared_distance_transform(mask)


def _box(mask: np.ndarray) -> tuple[int, int, int, int]:
    """First and one-past-last row and column (r0, r1, c0, c1) holding True cells of a
    non-empty 2-D bool mask."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _dilate_margin(objects: np.ndarray, c: float, margin: float) -> np.ndarray:
    """``ndimage.distance_transform_edt(~objects) * c <= margin + 1e-9`` for a 2-D bool mask
    with some True cell (cell c, margin in metres); the same mask.

    The transform is sqrt(di^2 + dj^2) of the offset to the nearest object cell, and the test
    grows with that integer: a cell passes iff an object cell lies at an offset whose squared
    length passes the same test (evaluated the same way). That is a dilation by a disc of
    offsets, done as ORs of shifted slices, row offset by row offset: a few passes for the
    usual 2.5-cell margin, where the transform costs 10x more. Larger discs use the transform.
    """
    reach = int((margin + 1e-9) / c) + 1  # the shortest axis offset that fails, but round-off
    d = np.arange(min(max(reach, 1), _DILATE_MAX_REACH) + 1)
    k = d[:, None] ** 2 + d[None, :] ** 2  # (di, dj) >= 0: squared lengths
    ok = np.sqrt(k.astype(np.float64)) * c <= margin + 1e-9
    half = ok.sum(axis=1) - 1  # widest |dj| that passes for each |di| (-1: none)
    if not 0 <= half[0] < len(d) - 1:  # a negative margin, or the disc may reach beyond d
        return distance_transform(~objects) * c <= margin + 1e-9
    wide = [objects]  # wide[m]: objects dilated by m cells along rows (OR over |dj| <= m)
    for m in range(1, int(half[0]) + 1):
        nxt = wide[-1].copy()
        nxt[:, m:] |= objects[:, :-m]  # object cell m columns to the left
        nxt[:, :-m] |= objects[:, m:]  # and to the right
        wide.append(nxt)
    out = wide[half[0]].copy()
    for di in range(1, len(half)):
        if half[di] < 0:
            continue
        src = wide[half[di]]
        out[di:] |= src[:-di]  # object cell di rows lower
        out[:-di] |= src[di:]  # and di rows higher
    return out


def _fill_convex(mask: np.ndarray, poly: np.ndarray, origin: np.ndarray, c: float) -> None:
    """Set the cells of mask (H, W) whose centres lie in the convex CCW polygon poly (K, 2)."""
    if len(poly) == 0:
        return
    h, w = mask.shape
    c0 = np.floor((poly.min(axis=0) - origin) / c).astype(np.int64).clip(0, [w - 1, h - 1])
    c1 = np.floor((poly.max(axis=0) - origin) / c).astype(np.int64).clip(0, [w - 1, h - 1])
    cols = np.arange(c0[0], c1[0] + 1)
    rows = np.arange(c0[1], c1[1] + 1)
    if len(poly) < 3:  # a point or a segment: its cells
        t = np.linspace(0.0, 1.0, 50)[:, None]
        seg = poly[0] + t * (poly[-1] - poly[0])
        ij = np.floor((seg - origin) / c).astype(np.int64)
        mask[ij[:, 1].clip(0, h - 1), ij[:, 0].clip(0, w - 1)] = True
        return
    gx, gy = np.meshgrid(origin[0] + (cols + 0.5) * c, origin[1] + (rows + 0.5) * c)
    inside = np.ones(gx.shape, dtype=bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):  # one pass per hull edge
        inside &= (b[0] - a[0]) * (gy - a[1]) - (b[1] - a[1]) * (gx - a[0]) >= -1e-12
    # Cells that contain a vertex count too (a thin object may cover no cell centre).
    ij = np.floor((poly - origin) / c).astype(np.int64)
    mask[ij[:, 1].clip(0, h - 1), ij[:, 0].clip(0, w - 1)] = True
    mask[np.ix_(rows, cols)] |= inside


def _empty(surface_id: int, c: float) -> FreeSpace:
    """A surface with no footprint cells: nothing free."""
    return FreeSpace(
        surface_id=int(surface_id),
        free_area=0.0,
        occupied_area=0.0,
        disc_center=np.full(2, np.nan),
        disc_radius=0.0,
        grid_origin=np.zeros(2),
        cell_size=c,
        free_mask=np.zeros((0, 0), dtype=bool),
    )
