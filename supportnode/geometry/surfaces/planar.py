"""The planar method's growth: per-voxel plane fits from moments, connection across
voxels whose planes continue into each other, size limits, and point labels."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from supportnode.geometry.linalg import sym3_eigen_entries
from supportnode.geometry.surfaces.footprint import _cells_key, _unique_cells, footprint_widths
from supportnode.geometry.surfaces.groups import _components, _median_by_group
from supportnode.geometry.voxels import KeyIndex, VoxelGrid, layered_offsets
from supportnode.params import SurfaceParams


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
    vx, vy = params.plane_voxel[0], params.plane_voxel[1]
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


def _label_points_planar(
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    tol_by_comp: np.ndarray,
    band: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Surface label of each point, in the grid's voxel order (``grid.order``), and its
    distance to the plane that labelled it (read only where labelled), metres.

    A point is on a surface when it lies within tolerance of the plane of a surface voxel
    in its own column: its own voxel, or the one just below or above (a noisy or
    layer-straddling surface spills into neighbouring layers). index:
    ``KeyIndex.build(grid.keys)``. band: the tolerance (K,) of surfaces (K,) for the points
    of voxels (K,) (the sensor's noise at their range), instead of ``tol_by_comp``."""
    n = len(grid.order)
    # int32 and no (N,) float fill: fresh pages cost more here than the arithmetic on them.
    sorted_labels = np.full(n, -1, dtype=np.int32)
    best = np.empty(n)  # distance of each labelled point to its plane; read where labelled
    sv = np.flatnonzero(surface_of_voxel >= 0)
    if len(sv) == 0:
        return sorted_labels, best
    # The voxels just above and below the surface voxels: those whose neighbour below or
    # above is one (ascending, as keys + 1 in z keep the voxels' order).
    up, down = index.neighbours_many(sv, [(0, 0, 1), (0, 0, -1)], grid.keys)
    # Work in the grid's voxel order on its corner-relative columns: contiguous, no gathers.
    # The three column neighbours (the voxel itself, the one above, the one below) in one
    # compiled loop, in that order: a labelled point changes surface only for a nearer plane
    # (the first pass finds none labelled: its voxels are distinct).
    on_up, on_down = up >= 0, down >= 0
    vsel = np.concatenate([sv, up[on_up], down[on_down]])
    t = np.concatenate([sv, sv[on_up], sv[on_down]])
    surf_v = surface_of_voxel[t]
    tol = tol_by_comp[surf_v] if band is None else band(surf_v, vsel)
    _label_by_plane_of(grid, planes, t, vsel, surf_v, tol, sorted_labels, best, True)
    return sorted_labels, best


def _plane_in(
    grid: VoxelGrid, mean: np.ndarray, normal: np.ndarray, vsel: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Planes through ``mean`` (K, 3) with ``normal`` (K, 3) (z > 0) as z = a + bx lx + by ly
    in the local frames (corner-relative) of the grid's voxels ``vsel`` (K,): (a, bx, by)."""
    bx, by = -normal[:, 0] / normal[:, 2], -normal[:, 1] / normal[:, 2]
    corner = grid.keys[vsel] * grid.size
    a = (
        (mean[:, 2] - corner[:, 2])
        + bx * (corner[:, 0] - mean[:, 0])
        + by * (corner[:, 1] - mean[:, 1])
    )
    return a, bx, by


def _label_by_plane_of(
    grid: VoxelGrid,
    planes: _Planes,
    t: np.ndarray,
    vsel: np.ndarray,
    label: np.ndarray,
    tol: np.ndarray,
    sorted_labels: np.ndarray,
    best: np.ndarray,
    nearer: bool,
) -> None:
    """Label, in place, the points of voxels ``vsel`` (K,) within ``tol`` (K,) of the planes
    of voxels ``t`` (K,) with ``label`` (K,) (see ``kernels.planes.label_by_planes``)."""
    # Imported here: importing the geometry (as the wire's types do) must not load numba.
    from supportnode.kernels.planes import label_by_planes

    a, bx, by = _plane_in(grid, planes.mean[t], planes.normal[t], vsel)
    label_by_planes(
        grid.local,
        grid.starts[vsel],
        grid.counts[vsel],
        (a, bx, by),
        label,
        tol,
        sorted_labels,
        best,
        nearer=nearer,
    )
