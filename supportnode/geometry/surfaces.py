"""Support surfaces: horizontal regions a robot can stand, land or put things on.

Two methods share one result type:
- ``seed``: Algorithm 1 of the report as published (voxels with more than ``p_min`` points, grown
  through horizontally adjacent voxels of the same height layer, regions of ``psi_min`` voxels).
- ``planar`` (default): per-voxel plane fits from moments; only flat, near-horizontal voxels grow;
  growth may cross height layers within ``max_step``; minimum area and width in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from supportnode.errors import InputError
from supportnode.geometry.linalg import sym3_eigen
from supportnode.geometry.normals import normals_at
from supportnode.geometry.voxels import (
    OUTER_INDEX,
    KeyIndex,
    VoxelGrid,
    horizontal_offsets,
    layered_offsets,
    voxelize,
)
from supportnode.params import SurfaceParams


def _r(value):
    """Round a float or array to 7 decimals for JSON (plain Python types)."""
    if np.ndim(value):
        return [round(float(v), 7) + 0.0 for v in value]
    return round(float(value), 7) + 0.0


@dataclass
class Surface:
    """One support surface. Lengths in metres, z up."""

    id: int
    height: float  # median z of the surface points
    area: float  # footprint area, m^2
    centroid: np.ndarray  # (3,) float64
    normal: np.ndarray  # (3,) float64 unit, z >= 0, from a plane fit to the surface points
    flatness: float  # rms distance of the surface points to that plane
    bbox_min: np.ndarray  # (3,) float64
    bbox_max: np.ndarray  # (3,) float64
    outline: list[np.ndarray]  # 2-D polygons (K, 2) float64 in x, y: [outer, hole, hole, ...]
    point_count: int
    voxel_count: int
    cells: np.ndarray  # (C, 2) int64 footprint cells (ix, iy) on the grid of size cell_size
    cell_size: tuple[float, float]  # (vx, vy) of the footprint grid; cell (i, j) spans
    # x in [i*vx, (i+1)*vx), y in [j*vy, (j+1)*vy)
    width: float = 0.0  # largest inscribed square-ish width of the footprint, m

    def to_dict(self) -> dict:
        """JSON-ready dictionary (no numpy types). Floats are rounded to 1e-7 (0.1 um, 1e-7 of
        a unit normal) so that the output does not depend on summation order."""
        return {
            "id": int(self.id),
            "height": _r(self.height),
            "area": _r(self.area),
            "width": _r(self.width),
            "centroid": _r(self.centroid),
            "normal": _r(self.normal),
            "flatness": _r(self.flatness),
            "bbox_min": _r(self.bbox_min),
            "bbox_max": _r(self.bbox_max),
            "outline": [np.round(p, 6).tolist() for p in self.outline],
            "point_count": int(self.point_count),
            "voxel_count": int(self.voxel_count),
        }


@dataclass
class SurfaceResult:
    """Surfaces sorted largest first (ids 0, 1, ... in that order) and a label per point."""

    surfaces: list[Surface]
    labels: np.ndarray  # (N,) int32: surface id of each input point, -1 when on none
    stats: dict = field(default_factory=dict)  # counts for diagnostics (voxels, candidates, ...)


def detect_surfaces(
    points: np.ndarray,
    params: SurfaceParams | None = None,
    sensor_origin: np.ndarray | None = None,
) -> SurfaceResult:
    """Find support surfaces in a gravity-aligned cloud.

    points: (N, 3) float, metres, z up. sensor_origin: (3,) sensor position in the same frame
    when known: a plane at or above the sensor shows it only its underside (a shelf board seen
    from below), which is no place to put anything. Returns surfaces sorted largest first and
    (N,) int32 labels.
    """
    params = params or SurfaceParams()
    pts = _check_points(points)
    size = np.asarray(params.voxel_size, dtype=np.float64)
    keep = None
    if params.normal_filter and len(pts):
        keep = _normal_filter_mask(pts, params)
    grid = voxelize(pts if keep is None else pts[keep], size)
    if params.method == "seed":
        surface_of_voxel, stats = _grow_seed(grid, params)
        voxel_labels = surface_of_voxel[grid.point_voxel]
        planes = None
    elif params.method == "planar":
        used = pts if keep is None else pts[keep]
        surface_of_voxel, planes, stats = _grow_planar(grid, params)
        tolerance = _surface_tolerance(surface_of_voxel, planes, params)
        absorbed = _absorb_clutter(used, grid, surface_of_voxel, planes, tolerance, params)
        stats["absorbed_voxels"] = len(absorbed)
        # Pieces of one board, split by the objects on it, meet once grown around them.
        sv = np.flatnonzero(surface_of_voxel >= 0)
        if len(sv):
            surface_of_voxel[sv] = _connect(
                grid.keys[sv], planes.mean[sv], planes.normal[sv], params
            )
            tolerance = _surface_tolerance(surface_of_voxel, planes, params)
        # Size limits apply to what a surface became: a board seen between objects is a
        # narrow strip until it has grown under and around them.
        stats["rejected_narrow"] = _filter_components(grid, surface_of_voxel, params)
        voxel_labels = _label_points_planar(used, grid, surface_of_voxel, planes, tolerance)
        stats["clutter_points_rejected"] = _reject_tilted_clutter(
            used, grid, voxel_labels, absorbed[surface_of_voxel[absorbed] >= 0], params
        )
    else:
        raise InputError(f"unknown surface method '{params.method}' (expected seed or planar)")
    labels = np.full(len(pts), -1, dtype=np.int64)
    if keep is None:
        labels[:] = voxel_labels
    else:
        labels[keep] = voxel_labels
    surfaces, labels = _summarise(pts, labels, grid, surface_of_voxel, params)
    if params.method == "planar":
        surfaces, labels = _drop_unfit(surfaces, labels, params, sensor_origin)
    stats.update(points=len(pts), voxels=len(grid.counts), surfaces=len(surfaces))
    if keep is not None:
        stats["normal_filter_removed"] = int(len(pts) - keep.sum())
    return SurfaceResult(surfaces=surfaces, labels=labels.astype(np.int32), stats=stats)


def _check_points(points: np.ndarray) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must be an (N, 3) array, got shape {pts.shape}")
    if not np.isfinite(pts).all():
        bad = int((~np.isfinite(pts).all(axis=1)).sum())
        raise InputError(f"{bad} points have NaN or Inf coordinates; drop them before detection")
    return pts


def _normal_filter_mask(pts: np.ndarray, params: SurfaceParams) -> np.ndarray:
    """The report's normal filter, applied to candidate points only (its own improvement):
    candidates are points in voxels that pass p_min; others cannot be surface points anyway."""
    from supportnode.geometry.normals import filter_vertical_normals

    grid = voxelize(pts, np.asarray(params.voxel_size, dtype=np.float64))
    candidate = (grid.counts > params.p_min)[grid.point_voxel]
    return (
        filter_vertical_normals(
            pts, candidate, params.normal_filter_k, params.normal_filter_max_tilt_deg
        )
        | ~candidate
    )


def _components(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Connected-component label of each of n nodes given undirected edges."""
    graph = coo_matrix((np.ones(len(src), dtype=np.int8), (src, dst)), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    return comp


def _grow_seed(grid: VoxelGrid, params: SurfaceParams) -> tuple[np.ndarray, dict]:
    """Algorithm 1: components of occupied voxels, horizontally adjacent in one layer."""
    occupied = np.flatnonzero(grid.counts > params.p_min)
    keys = grid.keys[occupied]
    index = KeyIndex.build(keys)
    src, dst = index.neighbour_pairs(keys, horizontal_offsets(params.connectivity))
    comp = _components(len(occupied), src, dst)
    size = np.bincount(comp)
    good = size[comp] >= params.psi_min
    surface_of_voxel = np.full(len(grid.counts), -1, dtype=np.int64)
    surface_of_voxel[occupied[good]] = comp[good]
    return surface_of_voxel, {"occupied_voxels": len(occupied)}


@dataclass
class _Planes:
    """Per-voxel plane of the planar method: a point on it and its unit normal (z > 0)."""

    mean: np.ndarray  # (M, 3)
    normal: np.ndarray  # (M, 3)
    roughness: np.ndarray  # (M,) rms distance to the plane, m


def _voxel_planes(grid: VoxelGrid, idx: np.ndarray, max_tilt_deg: float) -> _Planes:
    """Plane fits of the voxels ``idx`` from their moments.

    Points that are (nearly) collinear, such as one lidar ring crossing a voxel, leave the
    plane undetermined; such a voxel is taken as horizontal exactly when its line is."""
    cov = grid.covariances()[idx] if len(idx) else np.zeros((0, 3, 3))
    evals, normal = sym3_eigen(cov)
    evals = np.maximum(evals, 0.0)
    normal = np.where(normal[:, 2:3] < 0, -normal, normal)
    line_like = np.sqrt(evals[:, 1]) < 0.1 * np.sqrt(np.maximum(evals[:, 2], 1e-30))
    var_z = np.maximum(cov[:, 2, 2], 0.0)
    line_tilt_sin = np.sqrt(var_z / np.maximum(evals[:, 2], 1e-30))
    flat_line = line_like & (line_tilt_sin <= np.sin(np.radians(max_tilt_deg)))
    normal[flat_line] = (0.0, 0.0, 1.0)
    bad_line = line_like & ~flat_line
    normal[bad_line] = (1.0, 0.0, 0.0)  # a sloped line: certainly not a horizontal plane
    roughness = np.sqrt(np.where(line_like, np.minimum(evals[:, 1], var_z), evals[:, 0]))
    mean = grid.corners[idx] + grid.sums[idx] / grid.counts[idx, None]
    return _Planes(mean=mean, normal=normal, roughness=roughness)


def _grow_planar(grid: VoxelGrid, params: SurfaceParams) -> tuple[np.ndarray, _Planes, dict]:
    """Components of flat, near-horizontal voxels whose planes continue into each other."""
    dense = np.flatnonzero(grid.counts > max(params.p_min, 2))
    planes = _voxel_planes(grid, dense, params.max_tilt_deg)
    ok = (planes.normal[:, 2] >= np.cos(np.radians(params.max_tilt_deg))) & (
        planes.roughness <= params.max_roughness
    )
    cand = dense[ok]
    cplanes = _Planes(planes.mean[ok], planes.normal[ok], planes.roughness[ok])
    # Seeds for the clutter growth; gaps are bridged once, in the final connection.
    comp = _connect(grid.keys[cand], cplanes.mean, cplanes.normal, params, bridge=False)
    surface_of_voxel = np.full(len(grid.counts), -1, dtype=np.int64)
    surface_of_voxel[cand] = comp
    all_planes = _Planes(
        mean=np.zeros((len(grid.counts), 3)),
        normal=np.zeros((len(grid.counts), 3)),
        roughness=np.zeros(len(grid.counts)),
    )
    all_planes.mean[cand] = cplanes.mean
    all_planes.normal[cand] = cplanes.normal
    all_planes.roughness[cand] = cplanes.roughness
    stats = {
        "dense_voxels": len(dense),
        "candidate_voxels": len(cand),
        "components": int(comp.max()) + 1 if len(comp) else 0,
    }
    return surface_of_voxel, all_planes, stats


def _connect(
    keys: np.ndarray,
    mean: np.ndarray,
    normal: np.ndarray,
    params: SurfaceParams,
    bridge: bool = True,
) -> np.ndarray:
    """Component of each (M, 3)-keyed voxel: neighbours join when each one's plane, extended
    to the other's point, meets it within max_step (a step, a wall top beside a table or a
    shelf board above another does not join)."""
    index = KeyIndex.build(keys)
    offsets = layered_offsets(params.connectivity)
    if bridge and params.bridge_cells > 0:
        # Sparse scan lines far from a lidar leave empty cells between the rings of a floor.
        r = params.bridge_cells + 1
        far = np.array(
            [
                (dx, dy, dz)
                for dx in range(0, r + 1)
                for dy in range(-r, r + 1)
                for dz in (-1, 0, 1)
                if max(abs(dx), abs(dy)) >= 2 and (dx > 0 or dy > 0)
            ],
            dtype=np.int64,
        )
        offsets = np.concatenate([offsets, far])
    src, dst = index.neighbour_pairs(keys, offsets)
    d = mean[dst] - mean[src]
    gap_src = np.abs(np.einsum("ij,ij->i", d, normal[src])) / normal[src, 2]
    gap_dst = np.abs(np.einsum("ij,ij->i", d, normal[dst])) / normal[dst, 2]
    joined = np.maximum(gap_src, gap_dst) <= params.max_step
    return _components(len(keys), src[joined], dst[joined])


def _filter_components(grid: VoxelGrid, surface_of_voxel: np.ndarray, params: SurfaceParams) -> int:
    """Drop, in place, components smaller than min_area or narrower than min_width; returns
    how many were too narrow."""
    sv = np.flatnonzero(surface_of_voxel >= 0)
    if len(sv) == 0:
        return 0
    comp = surface_of_voxel[sv]
    keys = grid.keys[sv]
    vx, vy = params.voxel_size[0], params.voxel_size[1]
    # Footprint cells per component (a column holding two layers of one surface counts once).
    _, cell_comp = _unique_cells(keys[:, :2], comp)
    n_cells = np.bincount(cell_comp, minlength=int(comp.max()) + 1)
    big = np.flatnonzero(n_cells * vx * vy >= max(params.min_area, 1e-12))
    keep_comp = np.zeros(len(n_cells), dtype=bool)
    order = np.argsort(comp, kind="stable")
    bounds = np.searchsorted(comp[order], np.arange(len(n_cells) + 1))
    for c in big:  # one footprint raster per sizeable component (tens), not per voxel
        cells = keys[order[bounds[c] : bounds[c + 1]], :2]
        keep_comp[c] = footprint_width(cells, (vx, vy)) >= params.min_width
    surface_of_voxel[sv[~keep_comp[comp]]] = -1
    return int(len(big) - keep_comp.sum())


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
    raster, _ = rasterize_cells(cells, upsample=2, pad=1)
    if not raster.any():
        return 0.0
    dist = ndimage.distance_transform_edt(raster)
    return float(dist.max()) * min(cell_size)


def rasterize_cells(cells: np.ndarray, upsample: int = 1, pad: int = 1):
    """Boolean image of (C, 2) integer cells: image[iy, ix]; returns (image, origin cell)."""
    cells = np.asarray(cells, dtype=np.int64)
    origin = cells.min(axis=0) - pad
    c = cells - origin
    shape = (int(c[:, 1].max()) + 1 + pad, int(c[:, 0].max()) + 1 + pad)
    img = np.zeros(shape, dtype=bool)
    img[c[:, 1], c[:, 0]] = True
    if upsample > 1:
        img = np.repeat(np.repeat(img, upsample, axis=0), upsample, axis=1)
    return img, origin


def _surface_tolerance(
    surface_of_voxel: np.ndarray, planes: _Planes, params: SurfaceParams
) -> np.ndarray:
    """Point-to-plane tolerance per surface component, metres: ``point_tolerance``, widened
    to 3x the median voxel roughness on rough (noisy) surfaces."""
    sv = np.flatnonzero(surface_of_voxel >= 0)
    if len(sv) == 0:
        return np.zeros(0)
    comp = surface_of_voxel[sv]
    med = _median_by_group(planes.roughness[sv], comp, int(comp.max()) + 1)
    return np.maximum(params.point_tolerance, 3.0 * med)


def _absorb_clutter(
    pts: np.ndarray,
    grid: VoxelGrid,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    tolerance: np.ndarray,
    params: SurfaceParams,
) -> np.ndarray:
    """Grow surfaces into the cluttered voxels beside them, in place; returns the voxels added.

    A voxel holding a board and the foot of a lamp, or a floor and a wall's base, fails the
    flatness test although part of it is the surface. It joins a neighbouring surface voxel
    when enough of its points lie on that voxel's plane (carried over, not refitted, so growth
    cannot creep up an object) and they spread over the cell (not one edge line)."""
    steps = params.absorb_steps
    if steps <= 0 or not (surface_of_voxel >= 0).any():
        return np.zeros(0, dtype=np.int64)
    index = KeyIndex.build(grid.keys)
    offsets = layered_offsets(8)
    offsets = np.concatenate([offsets, -offsets])
    min_spread = 0.25 * np.asarray(params.voxel_size[:2])
    frontier = np.flatnonzero(surface_of_voxel >= 0)
    added = []
    for _ in range(steps):  # a few rings of voxels, each step vectorised
        src, dst = [], []
        for off in offsets:
            j = index.find(grid.keys[frontier] + off)
            ok = j >= 0
            src.append(frontier[ok])
            dst.append(j[ok])
        src, dst = np.concatenate(src), np.concatenate(dst)
        free = (surface_of_voxel[dst] < 0) & (grid.counts[dst] > params.p_min)
        src, dst = src[free], dst[free]
        if len(src) == 0:
            break
        # One trial per (voxel, surface): neighbours on one surface share its plane.
        pair = dst * (int(surface_of_voxel.max()) + 1) + surface_of_voxel[src]
        _, first_of_pair = np.unique(pair, return_index=True)
        src, dst = src[first_of_pair], dst[first_of_pair]
        # Every point of each candidate voxel against the plane of the surface voxel beside it.
        n_pts = grid.counts[dst]
        first = np.cumsum(n_pts) - n_pts
        pair_of_point = np.repeat(np.arange(len(dst)), n_pts)
        rank = np.arange(n_pts.sum()) - np.repeat(first, n_pts)
        point = grid.order[np.repeat(grid.starts[dst], n_pts) + rank]
        normal = planes.normal[src][pair_of_point]
        offset = pts[point] - planes.mean[src][pair_of_point]
        dist = np.abs(np.einsum("ij,ij->i", offset, normal)) / normal[:, 2]
        inlier = dist <= tolerance[surface_of_voxel[src]][pair_of_point]
        n_in = np.add.reduceat(inlier.astype(np.int64), first)
        xy = pts[point, :2]
        lo = np.minimum.reduceat(np.where(inlier[:, None], xy, np.inf), first, axis=0)
        hi = np.maximum.reduceat(np.where(inlier[:, None], xy, -np.inf), first, axis=0)
        # The inliers must themselves be a level patch: a ramp crosses a level plane in a
        # band that would otherwise pass, voxel after voxel along its contour.
        w = inlier.astype(np.float64)
        cnt = np.maximum(n_in, 1)[:, None]
        mean_in = np.add.reduceat(offset * w[:, None], first, axis=0) / cnt
        second = (
            np.stack(
                [np.add.reduceat(offset[:, a] * offset[:, b] * w, first) for a, b in OUTER_INDEX],
                axis=1,
            )
            / cnt
        )
        cov = np.empty((len(first), 3, 3))
        for col, (a, b) in enumerate(OUTER_INDEX):
            cov[:, a, b] = cov[:, b, a] = second[:, col] - mean_in[:, a] * mean_in[:, b]
        _, n_in_plane = sym3_eigen(cov)
        level = np.abs(n_in_plane[:, 2]) >= np.cos(np.radians(params.max_tilt_deg))
        good = (
            (n_in > params.p_min)
            & (n_in >= params.absorb_min_fraction * n_pts)
            & np.all(hi - lo >= min_spread, axis=1)
            & level
        )
        if not good.any():
            break
        # One surface per voxel: the neighbour explaining most of its points.
        cand = np.flatnonzero(good)
        order = np.lexsort((-n_in[cand], dst[cand]))
        cand = cand[order]
        keep = np.r_[True, dst[cand][1:] != dst[cand][:-1]]
        cand = cand[keep]
        j, s_vox = dst[cand], src[cand]
        surface_of_voxel[j] = surface_of_voxel[s_vox]
        planes.mean[j] = planes.mean[s_vox]
        planes.normal[j] = planes.normal[s_vox]
        planes.roughness[j] = planes.roughness[s_vox]
        added.append(j)
        frontier = j
    return np.concatenate(added) if added else np.zeros(0, dtype=np.int64)


def _reject_tilted_clutter(
    pts: np.ndarray,
    grid: VoxelGrid,
    labels: np.ndarray,
    absorbed: np.ndarray,
    params: SurfaceParams,
) -> int:
    """Unlabel, in place, surface points of cluttered voxels whose k-NN normal is tilted.

    The report's normal filter, run only where it matters (its own suggested improvement):
    within the point tolerance of a board lie the foot of the panel behind it and the bottom
    rim of the objects on it; their neighbourhoods are not level. Returns points unlabelled."""
    if len(absorbed) == 0:
        return 0
    in_absorbed = np.zeros(len(grid.counts), dtype=bool)
    in_absorbed[absorbed] = True
    query = np.flatnonzero((labels >= 0) & in_absorbed[grid.point_voxel])
    if len(query) == 0:
        return 0
    # Neighbours come from the cluttered voxels, those beside them in their layer (a wall's
    # foot, an object's rim) and those just above and below.
    index = KeyIndex.build(grid.keys)
    around = [absorbed]
    beside = [(dx, dy, 0) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
    for off in np.array([*beside, (0, 0, 1), (0, 0, -1)], dtype=np.int64):
        j = index.find(grid.keys[absorbed] + off)
        around.append(j[j >= 0])
    vox = np.unique(np.concatenate(around))
    n_pts = grid.counts[vox]
    first = np.cumsum(n_pts) - n_pts
    rank = np.arange(n_pts.sum()) - np.repeat(first, n_pts)
    support = pts[grid.order[np.repeat(grid.starts[vox], n_pts) + rank]]
    k = min(params.clutter_normal_k, len(support))
    if k < 3:
        return 0
    # An unbalanced tree builds in half the time and queries as fast on scan-like data.
    tree = cKDTree(support, balanced_tree=False, compact_nodes=False)
    normal, _ = normals_at(tree, support, pts[query], k)
    tilted = np.abs(normal[:, 2]) < np.cos(np.radians(params.normal_filter_max_tilt_deg))
    labels[query[tilted]] = -1
    return int(tilted.sum())


def _label_points_planar(
    pts: np.ndarray,
    grid: VoxelGrid,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    tol_by_comp: np.ndarray,
) -> np.ndarray:
    """A point is on a surface when it lies within tolerance of the plane of a surface voxel
    in its own column: its own voxel, or the one just below or above (a noisy or
    layer-straddling surface spills into neighbouring layers)."""
    labels = np.full(len(pts), -1, dtype=np.int64)
    sv = np.flatnonzero(surface_of_voxel >= 0)
    if len(sv) == 0:
        return labels
    index = KeyIndex.build(grid.keys[sv])
    # Work in the grid's voxel order on its corner-relative columns: contiguous, no gathers.
    lx, ly, lz = grid.local
    sorted_labels = np.full(len(pts), -1, dtype=np.int64)
    best = np.full(len(pts), np.inf)
    for dz in (0, -1, 1):  # three column neighbours, each vectorised over voxels and points
        hit = index.find(grid.keys + [0, 0, dz])
        vsel = np.flatnonzero(hit >= 0)
        if len(vsel) == 0:
            continue
        t = sv[hit[vsel]]
        # The plane of surface voxel t as z = A + bx*lx + by*ly in voxel vsel's local frame.
        n = planes.normal[t]
        bx, by = -n[:, 0] / n[:, 2], -n[:, 1] / n[:, 2]
        corner = grid.keys[vsel] * grid.size
        m = planes.mean[t]
        a = (m[:, 2] - corner[:, 2]) + bx * (corner[:, 0] - m[:, 0]) + by * (corner[:, 1] - m[:, 1])
        cnt = grid.counts[vsel]
        if len(vsel) == len(grid.counts):
            pos = np.arange(len(pts))
        else:
            pos = np.repeat(grid.starts[vsel] - (np.cumsum(cnt) - cnt), cnt) + np.arange(cnt.sum())
        dist = np.abs(
            lz[pos]
            - (np.repeat(a, cnt) + np.repeat(bx, cnt) * lx[pos] + np.repeat(by, cnt) * ly[pos])
        )
        surf = np.repeat(surface_of_voxel[t], cnt)
        better = (dist <= tol_by_comp[surf]) & (dist < best[pos])
        sorted_labels[pos[better]] = surf[better]
        best[pos[better]] = dist[better]
    labels[grid.order] = sorted_labels
    return labels


def _median_by_group(values: np.ndarray, groups: np.ndarray, n: int) -> np.ndarray:
    """Median of ``values`` within each group 0..n-1 (0 for empty groups)."""
    out = np.zeros(n)
    if len(values) == 0:
        return out
    order = np.lexsort((values, groups))
    g, v = groups[order], values[order]
    starts = np.searchsorted(g, np.arange(n))
    ends = np.searchsorted(g, np.arange(n), side="right")
    has = ends > starts
    mid = (starts + ends - 1) // 2
    mid2 = (starts + ends) // 2
    out[has] = 0.5 * (v[mid[has]] + v[np.minimum(mid2[has], len(v) - 1)])
    return out


def _summarise(
    pts: np.ndarray,
    comp_labels: np.ndarray,
    grid: VoxelGrid,
    surface_of_voxel: np.ndarray,
    params: SurfaceParams,
) -> tuple[list[Surface], np.ndarray]:
    """Per-surface properties from its points; surfaces sorted largest first, ids 0.."""
    on = comp_labels >= 0
    if not on.any():
        return [], np.full(len(pts), -1, dtype=np.int64)
    present = np.bincount(comp_labels[on])
    comps = np.flatnonzero(present)
    s_count = len(comps)
    remap = np.full(len(present) + 1, -1, dtype=np.int64)  # last entry maps -1 to -1
    remap[comps] = np.arange(s_count)
    # Surface points in voxel order (the grid's sort, reused): runs of one (voxel, surface)
    # are reduced first, contiguously; surfaces are then sums over their runs.
    in_order = on[grid.order]
    idx = grid.order[in_order]
    g = remap[comp_labels[idx]]
    vox = grid.point_voxel[idx]
    cut = np.empty(len(idx), dtype=bool)
    cut[0] = True
    cut[1:] = (vox[1:] != vox[:-1]) | (g[1:] != g[:-1])
    run = np.flatnonzero(cut)
    run_g, run_vox = g[run], vox[run]
    run_n = np.diff(np.append(run, len(idx)))
    corner = grid.keys[run_vox] * grid.size
    local = [c[in_order] for c in grid.local]
    r_sum = np.stack([np.add.reduceat(c, run) for c in local], axis=1)
    r_outer = np.stack([np.add.reduceat(local[a] * local[b], run) for a, b in OUTER_INDEX], axis=1)
    r_min = np.stack([np.minimum.reduceat(c, run) for c in local], axis=1) + corner
    r_max = np.stack([np.maximum.reduceat(c, run) for c in local], axis=1) + corner

    counts = np.bincount(run_g, weights=run_n, minlength=s_count)
    abs_sum = r_sum + corner * run_n[:, None]
    centroid = (
        np.stack(
            [np.bincount(run_g, weights=abs_sum[:, a], minlength=s_count) for a in range(3)], axis=1
        )
        / counts[:, None]
    )
    # Second moments about the surface centroid from each run's corner-relative moments.
    shift = corner - centroid[run_g]
    cov = np.empty((s_count, 3, 3))
    for col, (a, b) in enumerate(OUTER_INDEX):
        m = (
            r_outer[:, col]
            + shift[:, a] * r_sum[:, b]
            + shift[:, b] * r_sum[:, a]
            + run_n * shift[:, a] * shift[:, b]
        )
        cov[:, a, b] = cov[:, b, a] = np.bincount(run_g, weights=m, minlength=s_count) / counts
    evals, normal = sym3_eigen(cov)
    normal = np.where(normal[:, 2:3] < 0, -normal, normal)
    flatness = np.sqrt(np.maximum(evals[:, 0], 0.0))
    bmin = np.full((s_count, 3), np.inf)
    bmax = np.full((s_count, 3), -np.inf)
    np.minimum.at(bmin, run_g, r_min)
    np.maximum.at(bmax, run_g, r_max)
    # Height: the median of z, taken over runs weighted by their points (a run is one voxel's
    # share of a level surface, so its mean z stands for its points to within the roughness).
    height = _weighted_median(abs_sum[:, 2] / run_n, run_n, run_g, s_count)
    counts = counts.astype(np.int64)
    vcount = np.bincount(remap[surface_of_voxel[surface_of_voxel >= 0]], minlength=s_count)
    run_xy_min, run_xy_max = r_min[:, :2], r_max[:, :2]
    run_cells = grid.keys[run_vox, :2]
    vx, vy = float(params.voxel_size[0]), float(params.voxel_size[1])
    area, cells_of = _footprint_areas(
        run_cells, run_g, run_xy_min, run_xy_max, run_n, s_count, (vx, vy)
    )

    rank = np.lexsort((centroid[:, 1], centroid[:, 0], height, -counts, -area))
    new_id = np.empty(s_count, dtype=np.int64)
    new_id[rank] = np.arange(s_count)
    surfaces = []
    for sid, c in enumerate(rank):  # one entry per surface
        cells = cells_of[c]
        surfaces.append(
            Surface(
                id=sid,
                height=float(height[c]),
                area=float(area[c]),
                centroid=centroid[c],
                normal=normal[c],
                flatness=float(flatness[c]),
                bbox_min=bmin[c],
                bbox_max=bmax[c],
                outline=cells_outline(cells, (vx, vy)),
                point_count=int(counts[c]),
                voxel_count=int(vcount[c]),
                cells=cells,
                cell_size=(vx, vy),
                width=footprint_width(cells, (vx, vy)),
            )
        )
    new_id = np.append(new_id, -1)
    return surfaces, new_id[remap[comp_labels]]


def _drop_unfit(
    surfaces: list[Surface],
    labels: np.ndarray,
    params: SurfaceParams,
    sensor_origin: np.ndarray | None,
) -> tuple[list[Surface], np.ndarray]:
    """Final tests on each surface as a whole; ids stay in largest-first order.

    Size on measured areas and widths (growth could only bound them by whole cells); tilt of
    the plane fitted to all its points (sparse scan lines across a ramp look level voxel by
    voxel); seen from above when the sensor position is known."""
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
    if len(keep) == len(surfaces):
        return surfaces, labels
    new_id = np.full(len(surfaces) + 1, -1, dtype=np.int64)  # last entry maps -1 to -1
    for i, s in enumerate(keep):
        new_id[s.id] = i
        s.id = i
    return keep, new_id[labels]


def _weighted_median(
    values: np.ndarray, weights: np.ndarray, groups: np.ndarray, n: int
) -> np.ndarray:
    """Weighted median of ``values`` within each group 0..n-1."""
    order = np.lexsort((values, groups))
    v, w, g = values[order], weights[order].astype(np.float64), groups[order]
    cum = np.cumsum(w)
    start = np.searchsorted(g, np.arange(n))
    end = np.searchsorted(g, np.arange(n), side="right")
    before = np.where(start > 0, cum[np.maximum(start - 1, 0)], 0.0)
    half = before + 0.5 * (cum[end - 1] - before)
    pos = np.searchsorted(cum, half)
    return v[np.clip(pos, start, end - 1)]


def _footprint_areas(
    cells: np.ndarray,
    group: np.ndarray,
    xy_min: np.ndarray,
    xy_max: np.ndarray,
    n: np.ndarray,
    n_groups: int,
    cell_size: tuple[float, float],
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Area of each group's footprint and its (C, 2) cells, from per-voxel runs of points.

    Interior cells count whole; a border cell counts the part its points span, so a table
    edge that cuts a cell is not rounded up to the whole cell."""
    vx, vy = cell_size
    lo = cells.min(axis=0) - 1
    ck = cells - lo
    span = int(ck[:, 1].max()) + 2
    ncell = (int(ck[:, 0].max()) + 2) * span
    pair = group.astype(np.int64) * ncell + ck[:, 0] * span + ck[:, 1]
    order = np.argsort(pair, kind="stable")  # runs, not points: small
    ps = pair[order]
    first = np.flatnonzero(np.r_[True, ps[1:] != ps[:-1]])
    upair = ps[first]
    n_in = np.add.reduceat(n[order], first)
    ext = np.maximum.reduceat(xy_max[order], first, axis=0) - np.minimum.reduceat(
        xy_min[order], first, axis=0
    )
    # n uniform samples span (n-1)/(n+1) of an interval on average: undo that shrinkage.
    stretch = (n_in + 1) / np.maximum(n_in - 1, 1)
    frac = np.clip(ext[:, 0] * stretch / vx, 0, 1) * np.clip(ext[:, 1] * stretch / vy, 0, 1)
    # Too few points, or one scan line crossing the cell, say nothing about coverage.
    frac[(n_in < 3) | (frac < 0.05)] = 0.5
    interior = np.ones(len(upair), dtype=bool)
    for delta in (span, -span, 1, -1):  # the four edge neighbours of each cell
        q = upair + delta
        pos = np.minimum(np.searchsorted(upair, q), len(upair) - 1)
        interior &= upair[pos] == q
    frac[interior] = 1.0
    ug = upair // ncell
    area = np.bincount(ug, weights=frac, minlength=n_groups) * vx * vy
    local = upair % ncell
    out_cells = np.stack([local // span, local % span], axis=1) + lo
    bounds = np.searchsorted(ug, np.arange(n_groups + 1))
    return area, [out_cells[bounds[i] : bounds[i + 1]] for i in range(n_groups)]


def cells_outline(cells: np.ndarray, cell_size: tuple[float, float]) -> list[np.ndarray]:
    """Boundary rings of a footprint of (C, 2) integer cells, in metres.

    Returns (K, 2) float64 rings without the closing vertex: counter-clockwise rings bound the
    surface, clockwise rings are holes. The largest ring comes first. Cells that touch only at
    a corner give separate rings."""
    if len(cells) == 0:
        return []
    img, origin = rasterize_cells(cells, pad=1)
    filled = img
    # Directed boundary edges with the surface on their left, in vertex coordinates (x, y).
    edges = []
    jy, ix = np.nonzero(filled & ~np.roll(filled, 1, axis=0))  # nothing below: bottom edge
    edges.append(np.stack([ix, jy, ix + 1, jy], 1))
    jy, ix = np.nonzero(filled & ~np.roll(filled, -1, axis=1))  # nothing right
    edges.append(np.stack([ix + 1, jy, ix + 1, jy + 1], 1))
    jy, ix = np.nonzero(filled & ~np.roll(filled, -1, axis=0))  # nothing above
    edges.append(np.stack([ix + 1, jy + 1, ix, jy + 1], 1))
    jy, ix = np.nonzero(filled & ~np.roll(filled, 1, axis=1))  # nothing left
    edges.append(np.stack([ix, jy + 1, ix, jy], 1))
    e = np.concatenate(edges)
    nxt = _next_edge(e)
    n = len(e)
    graph = coo_matrix((np.ones(n, dtype=np.int8), (np.arange(n), nxt)), shape=(n, n))
    _, ring = connected_components(graph, directed=False)
    # Walk order without walking: cut each ring after its smallest edge index, then rank every
    # edge by its distance to the cut (pointer jumping: log2(E) vectorised rounds).
    root = np.full(ring.max() + 1, n, dtype=np.int64)
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
    order = np.lexsort((-dist, ring))
    bounds = np.searchsorted(ring[order], np.arange(ring.max() + 2))
    rings = []
    for k in range(ring.max() + 1):  # one entry per ring (outline and holes)
        r = e[order[bounds[k] : bounds[k + 1]], :2].astype(np.float64)
        rings.append((_drop_collinear(r) + origin) * np.asarray(cell_size))
    rings.sort(key=lambda r: -abs(_ring_area(r)))
    return rings


def _next_edge(e: np.ndarray) -> np.ndarray:
    """Successor of each directed boundary edge (E, 4: x0 y0 x1 y1): the edge leaving its end
    vertex, preferring the left turn so that cells touching at a corner make separate rings."""
    span = int(e[:, [1, 3]].max()) + 2  # vertex key x * span + y is unique since y < span
    start = e[:, 0] * span + e[:, 1]
    end = e[:, 2] * span + e[:, 3]
    by_start = np.argsort(start, kind="stable")
    first = np.searchsorted(start[by_start], end)
    count = np.searchsorted(start[by_start], end, side="right") - first
    a = by_start[np.minimum(first, len(e) - 1)]
    b = by_start[np.minimum(first + 1, len(e) - 1)]
    d = e[:, 2:] - e[:, :2]

    def left(j: np.ndarray) -> np.ndarray:  # z of d_i x d_j: +1 left, 0 straight, -1 right
        return d[:, 0] * d[j, 1] - d[:, 1] * d[j, 0]

    return np.where((count > 1) & (left(b) > left(a)), b, a)


def _drop_collinear(ring: np.ndarray) -> np.ndarray:
    prev = np.roll(ring, 1, axis=0)
    nxt = np.roll(ring, -1, axis=0)
    cross = (ring[:, 0] - prev[:, 0]) * (nxt[:, 1] - ring[:, 1]) - (ring[:, 1] - prev[:, 1]) * (
        nxt[:, 0] - ring[:, 0]
    )
    return ring[cross != 0]


def _ring_area(ring: np.ndarray) -> float:
    """Signed shoelace area: positive for counter-clockwise rings."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
