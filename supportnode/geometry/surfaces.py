"""Support surfaces: horizontal regions a robot can stand, land or put things on.

Two methods share one result type:
- ``seed``: Algorithm 1 of the report as published (voxels with more than ``p_min`` points, grown
  through horizontally adjacent voxels of the same height layer, regions of ``psi_min`` voxels).
- ``planar`` (default): per-voxel plane fits from moments; only flat, near-horizontal voxels grow;
  growth may cross height layers within ``max_step`` (flat objects lying on a surface, raised
  by a step, are cut out again); minimum area and width in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from supportnode.errors import InputError
from supportnode.geometry.linalg import sym3_eigen, sym3_eigen_entries
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
    used = pts if keep is None else pts[keep]
    grid = voxelize(used, size)
    # Point labels are kept in the grid's voxel order (contiguous per voxel) until the end.
    if params.method == "seed":
        surface_of_voxel, stats = _grow_seed(grid, params)
        sorted_labels = np.repeat(surface_of_voxel, grid.counts)
    elif params.method == "planar":
        index = KeyIndex.build(grid.keys)
        surface_of_voxel, planes, stats = _grow_planar(grid, index, params)
        tolerance = _surface_tolerance(surface_of_voxel, planes, params)
        absorbed = _absorb_clutter(grid, index, surface_of_voxel, planes, tolerance, params)
        stats["absorbed_voxels"] = len(absorbed)
        # Pieces of one board, split by the objects on it, meet once grown around them.
        sv = np.flatnonzero(surface_of_voxel >= 0)
        edges: list = []
        if len(sv):
            surface_of_voxel[sv] = _connect(
                grid, index, sv, planes.mean[sv], planes.normal[sv], params, edges=edges
            )
            tolerance = _surface_tolerance(surface_of_voxel, planes, params)
        # Size limits apply to what a surface became: a board seen between objects is a
        # narrow strip until it has grown under and around them.
        widths: dict[bytes, float] = {}
        stats["rejected_narrow"] = _filter_components(grid, surface_of_voxel, params, widths)
        # A cutting board or a plate joins the worktop it lies on: cut it out again.
        stats["plateau_voxels"] = (
            _drop_raised_plateaus(grid, surface_of_voxel, planes, tolerance, sv, *edges, params)
            if edges
            else 0
        )
        sorted_labels = _label_points_planar(grid, index, surface_of_voxel, planes, tolerance)
        vetted = _voxels_to_vet(grid, sorted_labels, surface_of_voxel, planes, absorbed, params)
        stats["clutter_points_rejected"] = _reject_tilted_clutter(
            grid, index, sorted_labels, vetted, params
        )
    else:
        raise InputError(f"unknown surface method '{params.method}' (expected seed or planar)")
    # Surface ids by the points' labels so far (lut[label], -1 for -1): one gather of all
    # points at the end, not one a stage.
    surfaces, lut = _summarise(
        grid, sorted_labels, surface_of_voxel, params, widths if params.method == "planar" else None
    )
    if params.method == "planar":
        surfaces, lut = _drop_unfit(grid, surfaces, sorted_labels, lut, params, sensor_origin)
    # Outlines only of the surfaces kept, all traced together.
    cell_size = (float(params.voxel_size[0]), float(params.voxel_size[1]))
    outlines = cells_outlines([s.cells for s in surfaces], cell_size)
    for s, outline in zip(surfaces, outlines, strict=True):
        s.outline = outline
    labels = np.full(len(pts), -1, dtype=np.int32)
    if keep is None:
        labels[grid.order] = lut[sorted_labels]
    else:
        used_labels = np.empty(len(used), dtype=np.int32)
        used_labels[grid.order] = lut[sorted_labels]
        labels[keep] = used_labels
    stats.update(points=len(pts), voxels=len(grid.counts), surfaces=len(surfaces))
    if keep is not None:
        stats["normal_filter_removed"] = int(len(pts) - keep.sum())
    return SurfaceResult(surfaces=surfaces, labels=labels, stats=stats)


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
    """Connected-component label of each of n nodes given undirected edges (components
    numbered by their first node, whatever the order of the edges)."""
    # The CSR arrays directly, in the dtypes csgraph works in: from a COO matrix, scipy's
    # conversions and checks cost twice the search on graphs of a few thousand edges.
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.bincount(src, minlength=n), out=indptr[1:])
    order = np.argsort(src, kind="stable")
    graph = csr_matrix((np.ones(len(src)), dst[order].astype(np.int32), indptr), shape=(n, n))
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


def _voxel_fits(
    grid: VoxelGrid,
    idx: np.ndarray,
    max_tilt_deg: float,
    entries: list[np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Plane fits of the voxels ``idx`` from their moments: unit normals (z >= 0),
    (len(idx), 3), and rms distances of the points to the plane, (len(idx),) m.
    entries: ``grid.covariance_entries(idx)`` when the caller has them.

    Points that are (nearly) collinear, such as one lidar ring crossing a voxel, leave the
    plane undetermined; such a voxel is taken as horizontal exactly when its line is."""
    # Covariance entries as columns: no (M, 3, 3) stack to build and take apart again.
    if entries is None:
        entries = grid.covariance_entries(idx)
    evals, normal = sym3_eigen_entries(*entries)
    evals = np.maximum(evals, 0.0)
    normal = np.where(normal[:, 2:3] < 0, -normal, normal)
    line_like = np.sqrt(evals[:, 1]) < 0.1 * np.sqrt(np.maximum(evals[:, 2], 1e-30))
    var_z = np.maximum(entries[2], 0.0)
    line_tilt_sin = np.sqrt(var_z / np.maximum(evals[:, 2], 1e-30))
    flat_line = line_like & (line_tilt_sin <= np.sin(np.radians(max_tilt_deg)))
    normal[flat_line] = (0.0, 0.0, 1.0)
    bad_line = line_like & ~flat_line
    normal[bad_line] = (1.0, 0.0, 0.0)  # a sloped line: certainly not a horizontal plane
    roughness = np.sqrt(np.where(line_like, np.minimum(evals[:, 1], var_z), evals[:, 0]))
    return normal, roughness


def _maybe_level(
    entries: list[np.ndarray], max_tilt_deg: float, max_roughness: float
) -> np.ndarray:
    """(M,) bool, True for every voxel whose fit by :func:`_voxel_fits` from its covariance
    ``entries`` (six (M,) columns in ``OUTER_INDEX`` order, m^2) can be level within
    ``max_tilt_deg`` and ``max_roughness`` m rough: a few false positives, no false negative.

    Necessary conditions, each with a slack far above the fit's round-off:
    - a plane: its normal n, within the tilt of z, for eigenvalue l <= r^2; the z row of
      the eigen equation gives var_z - l <= |(a02, a12)| tan(tilt), and l is at most the
      least eigenvalue of the xy block (interlacing);
    - a level line: var_z <= sin^2(tilt) times its largest eigenvalue, which is at most the
      largest absolute row sum g;
    - a fit too degenerate to give a normal (reported as +z): two equal least eigenvalues,
      so the least eigenvalues of the three 2x2 diagonal blocks, which lie between, agree."""
    if not 0.0 <= max_tilt_deg < 90.0:
        return np.ones(len(entries[0]), dtype=bool)
    a00, a11, a22, a01, a02, a12 = entries
    tilt = np.radians(max_tilt_deg)
    var_max = max_roughness**2
    g = np.maximum(np.abs(a00) + np.abs(a01) + np.abs(a02), np.abs(a01) + np.abs(a11) + np.abs(a12))
    g = np.maximum(g, np.abs(a02) + np.abs(a12) + np.abs(a22))
    slack = 1e-4 * g + 1e-5 * np.sqrt(g) + 1e-30

    def mu0(x: np.ndarray, y: np.ndarray, xy: np.ndarray) -> np.ndarray:
        return 0.5 * (x + y) - np.sqrt(0.25 * (x - y) ** 2 + xy * xy)

    m_xy, m_xz, m_yz = mu0(a00, a11, a01), mu0(a00, a22, a02), mu0(a11, a22, a12)
    c = np.sqrt(a02 * a02 + a12 * a12)
    plane = a22 <= np.minimum(var_max, m_xy) + c * (np.tan(tilt) * (1 + 1e-4)) + slack
    line = a22 <= np.sin(tilt) ** 2 * (1 + 1e-4) * np.maximum(g * (1 + 1e-4), 1e-30) + slack
    hi = np.maximum(np.maximum(m_xy, m_xz), m_yz)
    lo = np.minimum(np.minimum(m_xy, m_xz), m_yz)
    return plane | line | ((hi <= var_max + slack) & (hi - lo <= slack))


def _voxel_means(grid: VoxelGrid, idx: np.ndarray) -> np.ndarray:
    """(len(idx), 3) centroids of the voxels ``idx``, metres (as ``grid.means()[idx]``)."""
    return grid.keys[idx] * grid.size + grid.sums[idx] / grid.counts[idx, None]


def _grow_planar(
    grid: VoxelGrid, index: KeyIndex, params: SurfaceParams
) -> tuple[np.ndarray, _Planes, dict]:
    """Components of flat, near-horizontal voxels whose planes continue into each other.
    index: ``KeyIndex.build(grid.keys)``."""
    dense = grid.counts > max(params.p_min, 2)
    # The eigen solution costs ~20x the bound that rules most voxels out (walls, objects).
    # Entries of all voxels (nearly all are dense): no gathers of the moments.
    entries = grid.covariance_entries()
    fit = np.flatnonzero(dense & _maybe_level(entries, params.max_tilt_deg, params.max_roughness))
    normal, roughness = _voxel_fits(grid, fit, params.max_tilt_deg, [e[fit] for e in entries])
    ok = (normal[:, 2] >= np.cos(np.radians(params.max_tilt_deg))) & (
        roughness <= params.max_roughness
    )
    cand = fit[ok]
    # Centroids of the candidates only (a few percent of the voxels).
    cplanes = _Planes(_voxel_means(grid, cand), normal[ok], roughness[ok])
    # Seeds for the clutter growth; gaps are bridged once, in the final connection.
    comp = _connect(grid, index, cand, cplanes.mean, cplanes.normal, params, bridge=False)
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
        "dense_voxels": int(np.count_nonzero(dense)),
        "candidate_voxels": len(cand),
        "components": int(comp.max()) + 1 if len(comp) else 0,
    }
    return surface_of_voxel, all_planes, stats


def _connect(
    grid: VoxelGrid,
    index: KeyIndex,
    voxels: np.ndarray,
    mean: np.ndarray,
    normal: np.ndarray,
    params: SurfaceParams,
    bridge: bool = True,
    edges: list | None = None,
) -> np.ndarray:
    """Component of each of the (M,) ``voxels`` of the grid (``index``: its KeyIndex), with
    planes (M, 3) ``mean`` and ``normal``: neighbours join when each one's plane, extended
    to the other's point, meets it within max_step (a step, a wall top beside a table or a
    shelf board above another does not join). The joined pairs of adjacent voxels (src,
    dst: positions in ``voxels``), bridged ones left out, are appended to ``edges`` when
    given."""
    # Neighbours looked up in the grid's own index, then kept when among ``voxels``: the
    # pairs (and their order) of a KeyIndex of these voxels alone, without building one.
    position = np.full(len(grid.counts) + 1, -1, dtype=np.int64)  # last entry: absent (-1)
    position[voxels] = np.arange(len(voxels))

    def pairs(offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        j = position[index.neighbours_many(voxels, offsets, grid.keys)].ravel()
        hit = np.flatnonzero(j >= 0)
        return hit % max(len(voxels), 1), j[hit]

    src, dst = pairs(layered_offsets(params.connectivity))
    n_adjacent = len(src)
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
        far_src, far_dst = pairs(far)
        src, dst = np.concatenate([src, far_src]), np.concatenate([dst, far_dst])
    d = mean[dst] - mean[src]
    n_src, n_dst = normal[src], normal[dst]
    gap_src = np.abs(np.einsum("ij,ij->i", d, n_src)) / n_src[:, 2]
    gap_dst = np.abs(np.einsum("ij,ij->i", d, n_dst)) / n_dst[:, 2]
    joined = np.maximum(gap_src, gap_dst) <= params.max_step
    if edges is not None:
        near = joined[:n_adjacent]
        edges.extend((src[:n_adjacent][near], dst[:n_adjacent][near]))
    return _components(len(voxels), src[joined], dst[joined])


def _filter_components(
    grid: VoxelGrid,
    surface_of_voxel: np.ndarray,
    params: SurfaceParams,
    widths: dict[bytes, float] | None = None,
) -> int:
    """Drop, in place, components smaller than min_area or narrower than min_width; returns
    how many were too narrow. widths: filled with the width of each footprint measured, by
    ``_cells_key`` of its distinct cells (most surfaces end with the same cells)."""
    sv = np.flatnonzero(surface_of_voxel >= 0)
    if len(sv) == 0:
        return 0
    comp = surface_of_voxel[sv]
    keys = grid.keys[sv]
    vx, vy = params.voxel_size[0], params.voxel_size[1]
    # Footprint cells per component (a column holding two layers of one surface counts once).
    cell_lin, cell_comp = _unique_cells(keys[:, :2], comp)
    n_cells = np.bincount(cell_comp, minlength=int(comp.max()) + 1)
    big = np.flatnonzero(n_cells * vx * vy >= max(params.min_area, 1e-12))
    keep_comp = np.zeros(len(n_cells), dtype=bool)
    if len(big):  # footprint rasters of the sizeable components only (tens), not per voxel
        # The distinct cells, (component, x, y) ascending: a footprint's raster, and width,
        # do not depend on how many layers a column holds.
        lo = keys[:, :2].min(axis=0)
        span = int(keys[:, 1].max() - lo[1]) + 1
        xy = np.stack([cell_lin // span, cell_lin % span], axis=1) + lo
        bounds = np.searchsorted(cell_comp, np.arange(len(n_cells) + 1))
        cells = [xy[bounds[c] : bounds[c + 1]] for c in big]
        width = footprint_widths(cells, (vx, vy))
        keep_comp[big] = width >= params.min_width
        if widths is not None:
            widths.update(zip((_cells_key(c) for c in cells), width.tolist(), strict=True))
    surface_of_voxel[sv[~keep_comp[comp]]] = -1
    return int(len(big) - keep_comp.sum())


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
    step = np.maximum(params.plateau_min_step, tolerance)
    step_e = step[comp[src]]
    # A level neighbour of a step's voxel sees the step (dh) although the plane fitted across
    # the step, tilted, continues into both sides.
    cut = (np.abs(miss_dst) > step_e) | (np.abs(miss_src) > step_e) | (np.abs(dh) > step_e)
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
    # Rise of each piece across its cuts: the mean of both planes' misses, seen from it.
    cs, cd = src[cut], dst[cut]
    rise = 0.5 * (miss_dst[cut] - miss_src[cut])  # of src's piece over dst's
    rise = _median_by_group(np.r_[rise, -rise], np.r_[piece[cs], piece[cd]], n_pieces)
    cand = ~main & (of_piece >= 0) & (rise >= 0.5 * step[np.maximum(of_piece, 0)])
    if not cand.any():
        return 0
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
    drop = cand & small & (share >= _PLATEAU_MIN_AROUND)
    if not drop.any():
        return 0
    gone = drop[piece]
    # A voxel across a plateau's edge holds surface and the plateau's rim: its plane, tilted,
    # meets the plateau's top. It takes the plane of its most level neighbour when that is
    # more level (as absorbed clutter carries a plane over), so that its surface points stay
    # on and the plateau's are left off.
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
    surface_of_voxel[sv[gone]] = -1
    return int(gone.sum())


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
        dist = ndimage.distance_transform_edt(img)
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
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    tolerance: np.ndarray,
    params: SurfaceParams,
) -> np.ndarray:
    """Grow surfaces into the cluttered voxels beside them, in place; returns the voxels added.

    A voxel holding a board and the foot of a lamp, or a floor and a wall's base, fails the
    flatness test although part of it is the surface. It joins a neighbouring surface voxel
    when enough of its points lie on that voxel's plane (carried over, not refitted, so growth
    cannot creep up an object) and they spread over the cell (not one edge line). index:
    ``KeyIndex.build(grid.keys)``."""
    steps = params.absorb_steps
    if steps <= 0 or not (surface_of_voxel >= 0).any():
        return np.zeros(0, dtype=np.int64)
    offsets = layered_offsets(8)
    offsets = np.concatenate([offsets, -offsets])
    min_spread = 0.25 * np.asarray(params.voxel_size[:2])
    frontier = np.flatnonzero(surface_of_voxel >= 0)
    added = []
    for _ in range(steps):  # a few rings of voxels, each step vectorised
        j = index.neighbours_many(frontier, offsets, grid.keys)
        ok = j >= 0
        src, dst = np.broadcast_to(frontier, j.shape)[ok], j[ok]
        free = (surface_of_voxel[dst] < 0) & (grid.counts[dst] > params.p_min)
        src, dst = src[free], dst[free]
        if len(src) == 0:
            break
        # One trial per (voxel, surface): neighbours on one surface share its plane.
        pair = dst * (int(surface_of_voxel.max()) + 1) + surface_of_voxel[src]
        _, first_of_pair = np.unique(pair, return_index=True)
        src, dst = src[first_of_pair], dst[first_of_pair]
        # Every point of each candidate voxel against the plane of the surface voxel beside it,
        # read from the grid's contiguous corner-relative columns (1-D gathers of runs).
        n_pts = grid.counts[dst]
        first = np.cumsum(n_pts) - n_pts
        rank = np.arange(n_pts.sum()) - np.repeat(first, n_pts)
        pos = np.repeat(grid.starts[dst], n_pts) + rank
        # The plane's point relative to the candidate voxel's corner, then per point.
        rel = planes.mean[src] - grid.keys[dst] * grid.size
        nrm = planes.normal[src]
        # Column by column: numpy reduces 1-D arrays much faster than (P, 3) along axis 0.
        off = [grid.local[a][pos] - np.repeat(rel[:, a], n_pts) for a in range(3)]
        dist = np.abs(
            off[0] * np.repeat(nrm[:, 0] / nrm[:, 2], n_pts)
            + off[1] * np.repeat(nrm[:, 1] / nrm[:, 2], n_pts)
            + off[2]
        )
        inlier = dist <= np.repeat(tolerance[surface_of_voxel[src]], n_pts)
        n_in = np.add.reduceat(inlier.astype(np.int64), first)
        # The spread and level tests only for the trials with inliers enough (a few in ten).
        sel = np.flatnonzero((n_in > params.p_min) & (n_in >= params.absorb_min_fraction * n_pts))
        if len(sel) == 0:
            break
        n_sel = n_pts[sel]
        first_sel = np.cumsum(n_sel) - n_sel
        at = np.repeat(first[sel] - first_sel, n_sel) + np.arange(n_sel.sum())
        off = [o[at] for o in off]
        inlier = inlier[at]
        lo = np.stack(
            [np.minimum.reduceat(np.where(inlier, off[a], np.inf), first_sel) for a in range(2)],
            axis=1,
        )
        hi = np.stack(
            [np.maximum.reduceat(np.where(inlier, off[a], -np.inf), first_sel) for a in range(2)],
            axis=1,
        )
        # The inliers must themselves be a level patch: a ramp crosses a level plane in a
        # band that would otherwise pass, voxel after voxel along its contour.
        w = inlier.astype(np.float64)
        cnt = np.maximum(n_in[sel], 1)
        mean_in = [np.add.reduceat(off[a] * w, first_sel) / cnt for a in range(3)]
        # The inliers' covariance entries as columns, in OUTER_INDEX order.
        _, n_in_plane = sym3_eigen_entries(
            *(
                np.add.reduceat(off[a] * off[b] * w, first_sel) / cnt - mean_in[a] * mean_in[b]
                for a, b in OUTER_INDEX
            )
        )
        level = np.abs(n_in_plane[:, 2]) >= np.cos(np.radians(params.max_tilt_deg))
        good = np.zeros(len(dst), dtype=bool)
        good[sel] = np.all(hi - lo >= min_spread, axis=1) & level
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


def _voxels_to_vet(
    grid: VoxelGrid,
    sorted_labels: np.ndarray,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    absorbed: np.ndarray,
    params: SurfaceParams,
) -> np.ndarray:
    """Voxels whose surface points get the k-NN normal check: the cluttered voxels a surface
    grew into, and, on smooth surfaces, voxels that are no surface voxel themselves but have
    points within tolerance of the plane of the one above or below: the side face of a board
    or a floor slab just under its top edge. (On a noisy surface that layer holds the noise,
    whose k-NN normals scatter: it is left alone.)"""
    vet = absorbed[surface_of_voxel[absorbed] >= 0]
    sv = np.flatnonzero(surface_of_voxel >= 0)
    if len(sv) == 0:
        return vet
    comp = surface_of_voxel[sv]
    rough = _median_by_group(planes.roughness[sv], comp, int(comp.max()) + 1)
    smooth = 30.0 * rough <= params.point_tolerance
    label = np.maximum.reduceat(sorted_labels, grid.starts)  # a surface of the voxel, or -1
    beside = (surface_of_voxel < 0) & (label >= 0)
    beside[beside] = smooth[label[beside]]
    return np.union1d(vet, np.flatnonzero(beside))


def _reject_tilted_clutter(
    grid: VoxelGrid,
    index: KeyIndex,
    sorted_labels: np.ndarray,
    vetted: np.ndarray,
    params: SurfaceParams,
) -> int:
    """Unlabel, in place, surface points of the ``vetted`` voxels whose k-NN normal is tilted.

    sorted_labels: (N,) labels in the grid's voxel order; index: ``KeyIndex.build(grid.keys)``.
    The report's normal filter, run only where it matters (its own suggested improvement):
    within the point tolerance of a board lie the foot of the panel behind it, the bottom rim
    of the objects on it and the top of its side faces; their neighbourhoods are not level
    (:func:`_voxels_to_vet`). Returns points unlabelled."""
    if len(vetted) == 0:
        return 0
    # Neighbours come from the vetted voxels, those beside them in their layer (a wall's
    # foot, an object's rim) and those just above and below.
    beside = [(dx, dy, 0) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
    j = index.neighbours_many(vetted, [*beside, (0, 0, 1), (0, 0, -1)], grid.keys)
    vox = np.unique(np.concatenate([vetted, j[j >= 0]]))
    n_pts = grid.counts[vox]
    first = np.cumsum(n_pts) - n_pts
    pos = np.repeat(grid.starts[vox] - first, n_pts) + np.arange(n_pts.sum())
    # Support points in voxel order (queries in that order find their neighbours in cache),
    # relative to one corner: precise far from the origin, no (N, 3) row gathers.
    rel = np.repeat(grid.keys[vox] - grid.keys[vox[0]], n_pts, axis=0) * grid.size
    support = np.stack([grid.local[a][pos] for a in range(3)], axis=1) + rel
    in_vetted = np.zeros(len(grid.counts), dtype=bool)
    in_vetted[vetted] = True
    query = np.flatnonzero(np.repeat(in_vetted[vox], n_pts) & (sorted_labels[pos] >= 0))
    k = min(params.clutter_normal_k, len(support))
    if len(query) == 0 or k < 3:
        return 0
    # An unbalanced tree builds in half the time and queries as fast on scan-like data.
    tree = cKDTree(support, balanced_tree=False, compact_nodes=False)
    normal, _ = normals_at(tree, support, support[query], k)
    tilted = np.abs(normal[:, 2]) < np.cos(np.radians(params.normal_filter_max_tilt_deg))
    sorted_labels[pos[query[tilted]]] = -1
    return int(tilted.sum())


def _label_points_planar(
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    tol_by_comp: np.ndarray,
) -> np.ndarray:
    """Surface label of each point, in the grid's voxel order (``grid.order``).

    A point is on a surface when it lies within tolerance of the plane of a surface voxel
    in its own column: its own voxel, or the one just below or above (a noisy or
    layer-straddling surface spills into neighbouring layers). index:
    ``KeyIndex.build(grid.keys)``."""
    n = len(grid.order)
    # int32 and no (N,) float fill: fresh pages cost more here than the arithmetic on them.
    sorted_labels = np.full(n, -1, dtype=np.int32)
    sv = np.flatnonzero(surface_of_voxel >= 0)
    if len(sv) == 0:
        return sorted_labels
    # The voxels just above and below the surface voxels: those whose neighbour below or
    # above is one (ascending, as keys + 1 in z keep the voxels' order).
    up, down = index.neighbours_many(sv, [(0, 0, 1), (0, 0, -1)], grid.keys)
    # Work in the grid's voxel order on its corner-relative columns: contiguous, no gathers.
    lx, ly, lz = grid.local
    best = np.empty(n)  # distance of each labelled point to its plane; read where labelled
    for dz in (0, -1, 1):  # three column neighbours, each vectorised over voxels and points
        if dz == 0:
            vsel = sv
            t = sv
        else:
            hit = up if dz < 0 else down
            on = hit >= 0
            vsel, t = hit[on], sv[on]
            if len(vsel) == 0:
                continue
        # The plane of surface voxel t as z = A + bx*lx + by*ly in voxel vsel's local frame.
        nrm = planes.normal[t]
        bx, by = -nrm[:, 0] / nrm[:, 2], -nrm[:, 1] / nrm[:, 2]
        corner = grid.keys[vsel] * grid.size
        m = planes.mean[t]
        a = (m[:, 2] - corner[:, 2]) + bx * (corner[:, 0] - m[:, 0]) + by * (corner[:, 1] - m[:, 1])
        cnt = grid.counts[vsel]
        if len(vsel) == len(grid.counts):
            pos = np.arange(n)
        else:
            pos = np.repeat(grid.starts[vsel] - (np.cumsum(cnt) - cnt), cnt) + np.arange(cnt.sum())
        dist = np.abs(
            lz[pos]
            - (np.repeat(a, cnt) + np.repeat(bx, cnt) * lx[pos] + np.repeat(by, cnt) * ly[pos])
        )
        # Per voxel, then repeated: the tolerance of each voxel's surface, not a gather per point.
        surf_v = surface_of_voxel[t]
        better = dist <= np.repeat(tol_by_comp[surf_v], cnt)
        if dz != 0:  # a labelled point changes surface only for a nearer plane
            seen = np.flatnonzero(better & (sorted_labels[pos] >= 0))
            better[seen] = dist[seen] < best[pos[seen]]
        idx = np.flatnonzero(better)
        at = pos[idx]
        sorted_labels[at] = np.repeat(surf_v, cnt)[idx]
        best[at] = dist[idx]
    return sorted_labels


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
    grid: VoxelGrid,
    sorted_labels: np.ndarray,
    surface_of_voxel: np.ndarray,
    params: SurfaceParams,
    widths: dict[bytes, float] | None = None,
) -> tuple[list[Surface], np.ndarray]:
    """Per-surface properties from its points; surfaces sorted largest first, ids 0..

    sorted_labels: (N,) component of each point in the grid's voxel order, -1 for none;
    returns the surfaces and each component's surface id: ``lut[sorted_labels]`` (int32,
    its last entry -1 for the points on none). widths: footprint widths already
    measured, by ``_cells_key`` of the footprint (see :func:`_filter_components`)."""
    at = np.flatnonzero(sorted_labels >= 0)
    if len(at) == 0:
        return [], np.full(1, -1, dtype=np.int32)
    lab = sorted_labels[at]
    present = np.bincount(lab)
    comps = np.flatnonzero(present)
    s_count = len(comps)
    remap = np.full(len(present) + 1, -1, dtype=np.int64)  # last entry maps -1 to -1
    remap[comps] = np.arange(s_count)
    # Runs of one (voxel, surface) are reduced first; surfaces are then sums over their runs.
    # Most surface voxels hold points of one surface only: their run is the whole voxel, whose
    # moments the grid already has. Only mixed voxels are reduced point by point.
    # Only the labelled points are read (a few of all): a voxel is pure when all its points
    # are labelled, with one surface.
    at_vox = np.searchsorted(grid.starts, at, side="right") - 1
    first = np.flatnonzero(np.r_[True, at_vox[1:] != at_vox[:-1]])
    vv = at_vox[first]
    n_on = np.diff(np.append(first, len(at)))
    pure = (n_on == grid.counts[vv]) & (
        np.minimum.reduceat(lab, first) == np.maximum.reduceat(lab, first)
    )
    pure_vox = vv[pure]
    mixed = np.repeat(~pure, n_on)
    g = remap[lab[mixed]]
    vox = at_vox[mixed]
    cut = np.empty(len(g), dtype=bool)
    cut[:1] = True
    cut[1:] = (vox[1:] != vox[:-1]) | (g[1:] != g[:-1])
    run = np.flatnonzero(cut)
    local = [c[at[mixed]] for c in grid.local]

    def reduce_runs(ufunc: np.ufunc, values: list[np.ndarray], pure_values: np.ndarray):
        if len(run) == 0:  # reduceat needs at least one run
            return pure_values
        mixed_values = np.stack([ufunc.reduceat(v, run) for v in values], axis=1)
        return np.concatenate([pure_values, mixed_values])

    run_g = np.concatenate([remap[sorted_labels[grid.starts[pure_vox]]], g[run]])
    run_vox = np.concatenate([pure_vox, vox[run]])
    run_n = np.concatenate([grid.counts[pure_vox], np.diff(np.append(run, len(g)))])
    corner = grid.keys[run_vox] * grid.size
    r_sum = reduce_runs(np.add, local, grid.sums[pure_vox])
    r_outer = reduce_runs(
        np.add, [local[a] * local[b] for a, b in OUTER_INDEX], grid.outer[pure_vox]
    )
    # Extremes of the pure voxels from their own points.
    if len(pure_vox):
        pure_local = [c[at[~mixed]] for c in grid.local]
        bounds = np.cumsum(grid.counts[pure_vox]) - grid.counts[pure_vox]
        v_min = np.stack([np.minimum.reduceat(c, bounds) for c in pure_local], axis=1)
        v_max = np.stack([np.maximum.reduceat(c, bounds) for c in pure_local], axis=1)
    else:
        v_min = v_max = np.zeros((0, 3))
    r_min = reduce_runs(np.minimum, local, v_min) + corner
    r_max = reduce_runs(np.maximum, local, v_max) + corner

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
    width = np.array(
        [-1.0 if widths is None else widths.get(_cells_key(c), -1.0) for c in cells_of]
    )
    todo = np.flatnonzero(width < 0)
    if len(todo):
        width[todo] = footprint_widths([cells_of[i] for i in todo], (vx, vy))
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
                outline=[],  # traced once the surface is kept (detect_surfaces)
                point_count=int(counts[c]),
                voxel_count=int(vcount[c]),
                cells=cells,
                cell_size=(vx, vy),
                width=float(width[c]),
            )
        )
    new_id = np.append(new_id, -1).astype(np.int32)
    return surfaces, new_id[remap]


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
    max_area, max_height = params.object_top_max_area, params.object_top_max_height
    small = [i for i, s in enumerate(surfaces) if s.area < max_area]
    if max_area <= 0 or len(surfaces) < 2 or not small:
        return out
    cells = np.concatenate([s.cells for s in surfaces])
    lo = cells.min(axis=0) - 1
    span = int(cells[:, 1].max() - lo[1]) + 2

    def lin(c: np.ndarray) -> np.ndarray:  # cells (C, 2) -> linear keys on a padded grid
        return (c[:, 0] - lo[0]) * span + (c[:, 1] - lo[1])

    keys = [lin(s.cells) for s in surfaces]  # distinct cells already
    ring8 = np.array([span * dx + dy for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy])
    edge4 = np.array([span, -span, 1, -1])
    below = {}  # small face -> the surfaces lying around it, a little lower, not plainly seen
    for i in small:
        s = surfaces[i]
        ring = np.setdiff1d(keys[i][:, None] + ring8, keys[i])
        inner = keys[i][np.isin(keys[i][:, None] + edge4, keys[i]).all(axis=1)]
        below[i] = [
            j
            for j, t in enumerate(surfaces)
            if params.max_step < s.height - t.height <= max_height
            and np.isin(ring, keys[j]).mean() >= _TOP_MIN_AROUND
            # Cells are coarse: a box's footprint cells also hold the worktop beside it, but
            # a surface in most of the inner cells is plainly seen under the face.
            and not (len(inner) and np.isin(inner, keys[j]).mean() >= 0.5)
        ]
        if not below[i]:
            del below[i]  # nothing around it to stand on, or plainly seen under it
    if not below:
        return out
    # Points of these faces and of the surfaces around them, in the faces' columns: xy and
    # surface id, thinned to a bounded number (the test compares densities).
    ids = np.array(
        sorted(
            {surfaces[i].id for i in below} | {surfaces[j].id for b in below.values() for j in b}
        )
    )
    voxel_cell = lin(grid.keys[:, :2])  # each voxel's column, for this and _load
    vox = np.flatnonzero(np.isin(voxel_cell, np.concatenate([keys[i] for i in below])))
    n_pts = grid.counts[vox]
    pos = np.repeat(grid.starts[vox] - (np.cumsum(n_pts) - n_pts), n_pts) + np.arange(n_pts.sum())
    sid = lut[labels[pos]]
    pos = pos[np.isin(sid, ids)]
    step = max(1, len(pos) // _TOP_MAX_POINTS)
    pos = pos[::step]
    v = np.searchsorted(grid.starts, pos, side="right") - 1
    xy = (
        np.stack([grid.local[0][pos], grid.local[1][pos]], axis=1)
        + grid.keys[v, :2] * grid.size[:2]
    )
    sid = lut[labels[pos]]
    for i, under in below.items():
        s = surfaces[i]
        inner, (origin, cell) = _inner_footprint(xy[sid == s.id], s.area)
        if inner is None:
            continue  # too small to tell what lies under it: keep
        for j in under:
            t = surfaces[j]
            f = np.floor((xy[sid == t.id] - origin) / cell).astype(np.int64)
            ok = np.all((f >= 0) & (f < inner.shape[::-1]), axis=1)
            seen = int(inner[f[ok, 1], f[ok, 0]].sum())
            expected = t.point_count / step / max(t.area, 1e-9) * inner.sum() * cell**2
            if seen <= _TOP_MAX_SEEN * expected:
                out[i] = True
                break
    for i in np.flatnonzero(out):  # a few object tops: do they carry something?
        out[i] = (
            _load(grid, labels, lut, keys[i], voxel_cell, surfaces[i].height, params)
            < _TOP_MIN_LOAD
        )
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
    img = ndimage.binary_fill_holes(ndimage.binary_closing(img))
    img = ndimage.binary_erosion(ndimage.binary_opening(img))
    return (img if img.any() else None), (origin, cell)


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
    # Directed boundary edges with the surface on their left, in vertex coordinates (x, y)
    # of each footprint's own raster, ordered as one footprint's edges alone would be: by
    # footprint, then side, then row and column.
    # (np.roll wraps around, onto the empty border of a raster.)
    sides = (
        (0, 1, lambda x, y: (x, y, x + 1, y)),  # nothing below: bottom edge
        (1, -1, lambda x, y: (x + 1, y, x + 1, y + 1)),  # nothing right
        (0, -1, lambda x, y: (x + 1, y + 1, x, y + 1)),  # nothing above
        (1, 1, lambda x, y: (x, y + 1, x, y)),  # nothing left
    )
    edges, owner = [], []
    for members, filled, first_row in _stacked_rasters(cells_list, upsample=1):
        for side, (axis, shift, edge) in enumerate(sides):
            jy, ix = np.nonzero(filled & ~np.roll(filled, shift, axis=axis))
            m = np.searchsorted(first_row, jy, side="right") - 1
            edges.append(np.stack(edge(ix, jy - first_row[m]), 1))
            owner.append(members[m] * 4 + side)
    owner = np.concatenate(owner)
    by = np.argsort(owner, kind="stable")
    e = np.concatenate(edges)[by]
    owner = owner[by] // 4
    nxt = _next_edge(e, owner)
    n = len(e)
    ring = _components(n, np.arange(n), nxt)
    # Walk order without walking: cut each ring after its smallest edge index, then rank every
    # edge by its distance to the cut (pointer jumping: log2(E) vectorised rounds).
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
    order = np.lexsort((-dist, ring))
    bounds = np.searchsorted(ring[order], np.arange(n_rings + 1))
    # Collinear vertices dropped (the cross product of the edges in and out is exact on
    # integers), every ring at once: its previous and next vertex wrap around within it.
    v = e[order, :2].astype(np.float64)
    ring_of = ring[order]
    at = np.arange(n)
    prev = np.where(at == bounds[ring_of], bounds[ring_of + 1] - 1, at - 1)
    after = np.where(at == bounds[ring_of + 1] - 1, bounds[ring_of], at + 1)
    cross = (v[:, 0] - v[prev, 0]) * (v[after, 1] - v[:, 1]) - (v[:, 1] - v[prev, 1]) * (
        v[after, 0] - v[:, 0]
    )
    keep = cross != 0
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
