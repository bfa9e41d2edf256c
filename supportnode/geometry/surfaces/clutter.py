"""Cluttered voxels beside a surface: grown into when their points lie on its plane,
and their tilted points (k-NN normals) taken off again."""

from __future__ import annotations

import numpy as np

from supportnode.geometry.linalg import sym3_eigen_entries
from supportnode.geometry.normals import normals_among
from supportnode.geometry.surfaces.groups import _median_by_group
from supportnode.geometry.surfaces.planar import _Planes
from supportnode.geometry.voxels import OUTER_INDEX, KeyIndex, VoxelGrid, layered_offsets
from supportnode.params import SurfaceParams


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
    cannot creep up an object; tilted by a step, the surface's around it instead) and they
    spread over the cell (not one edge line). index:
    ``KeyIndex.build(grid.keys)``."""
    steps = params.absorb_steps
    if steps <= 0 or not (surface_of_voxel >= 0).any():
        return np.zeros(0, dtype=np.int64)
    offsets = layered_offsets(8)
    offsets = np.concatenate([offsets, -offsets])
    frontier = np.flatnonzero(surface_of_voxel >= 0)
    normal = planes.normal.copy()  # what each surface voxel's plane carries over
    added = []
    for step in range(steps):  # a few rings of voxels, each step vectorised
        src, dst = _trials(grid, index, surface_of_voxel, frontier, offsets, params.p_min)
        if len(src) == 0:
            break
        if step == 0:
            _untilt_steps(grid, index, surface_of_voxel, planes, np.unique(src), normal, params)
        good = _fits(grid, surface_of_voxel, planes, normal[src], tolerance, src, dst, params)
        if not good.any():
            break
        # One surface per voxel: the neighbour explaining most of its points.
        cand = np.flatnonzero(good)
        order = np.lexsort((-good[cand], dst[cand]))
        cand = cand[order]
        keep = np.r_[True, dst[cand][1:] != dst[cand][:-1]]
        cand = cand[keep]
        j, s_vox = dst[cand], src[cand]
        surface_of_voxel[j] = surface_of_voxel[s_vox]
        planes.mean[j] = planes.mean[s_vox]
        planes.normal[j] = normal[j] = normal[s_vox]
        planes.roughness[j] = planes.roughness[s_vox]
        added.append(j)
        frontier = j
    return np.concatenate(added) if added else np.zeros(0, dtype=np.int64)


# A voxel of a smooth surface tilted more than this from the surface around it holds a step
# (a board and a plank's foot), not the surface's own slant (on a noisy one: its noise).
_STEP_TILT_DEG = 2.0


def _untilt_steps(
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    voxels: np.ndarray,
    normal: np.ndarray,
    params: SurfaceParams,
) -> None:
    """Give, in place in ``normal`` (V, 3), each of the surface ``voxels`` of a smooth surface
    that a step tilts the normal of the surface around it. A voxel holding a board and the
    foot of a plank 1 cm up on it fits a plane tilted 5-9 deg, which, carried ring after ring,
    left the board 2 cm off it 20 cm away."""
    cos_step = np.cos(np.radians(_STEP_TILT_DEG))
    # A level voxel keeps its own plane (the common case: checked first, it costs nothing).
    voxels = voxels[planes.normal[voxels, 2] < cos_step]
    if len(voxels) == 0:
        return
    voxels = voxels[_smooth(surface_of_voxel, planes, params)[surface_of_voxel[voxels]]]
    if len(voxels) == 0:
        return
    around = _local_normals(grid, index, surface_of_voxel, planes, voxels)
    own = planes.normal[voxels]
    step = np.einsum("ij,ij->i", around, own) < cos_step
    normal[voxels[step]] = around[step]


def _smooth(surface_of_voxel: np.ndarray, planes: _Planes, params: SurfaceParams) -> np.ndarray:
    """(S,) bool: which surfaces are smooth (their voxels' median roughness a thirtieth of the
    point tolerance or less: noise-free, not a depth camera's or a noisy lidar's)."""
    sv = np.flatnonzero(surface_of_voxel >= 0)
    comp = surface_of_voxel[sv]
    rough = _median_by_group(planes.roughness[sv], comp, int(comp.max()) + 1)
    return 30.0 * rough <= params.point_tolerance


def _local_normals(
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    sv: np.ndarray,
) -> np.ndarray:
    """(S, 3) for each of the surface voxels sv (S,), the median (axis by axis, renormalised)
    of the normals of the voxels of its surface around it (itself and its 26 neighbours).
    One voxel that a step tilts does not tilt it; a ramp's voxels keep the ramp's."""
    half = layered_offsets(8)
    offsets = np.concatenate([np.zeros((1, 3), np.int64), half, -half])
    j = index.neighbours_many(sv, offsets, grid.keys)  # (K, S)
    same = (j >= 0) & (surface_of_voxel[j.clip(0)] == surface_of_voxel[sv][None, :])
    # The median of each column's valid rows: sorted, the missing ones (NaN) last.
    nrm = np.sort(np.where(same[:, :, None], planes.normal[j.clip(0)], np.nan), axis=0)
    n = same.sum(axis=0)[None, :, None]  # itself is always there: n >= 1
    lo = np.take_along_axis(nrm, (n - 1) // 2, axis=0)[0]
    hi = np.take_along_axis(nrm, n // 2, axis=0)[0]
    med = 0.5 * (lo + hi)
    return med / np.maximum(np.linalg.norm(med, axis=1, keepdims=True), 1e-12)


def _trials(
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    frontier: np.ndarray,
    offsets: np.ndarray,
    p_min: int,
) -> tuple[np.ndarray, np.ndarray]:
    """(src, dst): the surface voxels of ``frontier`` and the free voxels beside them (more
    than ``p_min`` points, on no surface) to try on their planes, one per (voxel, surface)."""
    j = index.neighbours_many(frontier, offsets, grid.keys)
    ok = j >= 0
    src, dst = np.broadcast_to(frontier, j.shape)[ok], j[ok]
    free = (surface_of_voxel[dst] < 0) & (grid.counts[dst] > p_min)
    src, dst = src[free], dst[free]
    # One trial per (voxel, surface): neighbours on one surface share its plane.
    pair = dst * (int(surface_of_voxel.max()) + 1) + surface_of_voxel[src]
    _, first_of_pair = np.unique(pair, return_index=True)
    return src[first_of_pair], dst[first_of_pair]


def _fits(
    grid: VoxelGrid,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    nrm: np.ndarray,
    tolerance: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    params: SurfaceParams,
) -> np.ndarray:
    """(T,) int: for each trial, its inliers on the plane through ``src``'s point with normal
    ``nrm`` (T, 3) when they are enough, spread over the cell and level (0 for a failed
    trial): every point of each candidate voxel ``dst`` against the plane beside it, read
    from the grid's contiguous corner-relative columns (1-D gathers of runs)."""
    # Imported here: importing the geometry (as the wire's types do) must not load numba.
    from supportnode.kernels.planes import inlier_moments, plane_inliers

    n_pts = grid.counts[dst]
    # The plane's point relative to the candidate voxel's corner, then per point.
    rel = planes.mean[src] - grid.keys[dst] * grid.size
    bx, by = nrm[:, 0] / nrm[:, 2], nrm[:, 1] / nrm[:, 2]
    tol = tolerance[surface_of_voxel[src]]
    # Counted in one compiled pass over the trials' points (most trials fail here).
    n_in = plane_inliers(grid.local, grid.starts[dst], n_pts, rel, (bx, by), tol)
    out = np.zeros(len(dst), dtype=np.int64)
    # The spread and level tests only for the trials with inliers enough (a few in ten).
    sel = np.flatnonzero((n_in > params.p_min) & (n_in >= params.absorb_min_fraction * n_pts))
    if len(sel) == 0:
        return out
    lo, hi, sums, outer = inlier_moments(
        grid.local, grid.starts[dst[sel]], n_pts[sel], rel[sel], (bx[sel], by[sel]), tol[sel]
    )
    spread, level = _spread_level(lo, hi, sums, outer, n_in[sel], params)
    out[sel] = np.where(spread & level, n_in[sel], 0)
    return out


def _spread_level(
    lo: np.ndarray,
    hi: np.ndarray,
    sums: np.ndarray,
    outer: np.ndarray,
    n_in: np.ndarray,
    params: SurfaceParams,
) -> tuple[np.ndarray, np.ndarray]:
    """Per trial (its inliers' x, y box lo, hi (T, 2), sums (T, 3) and products (T, 6), see
    `kernels.planes.inlier_moments`, and count n_in (T,)): whether they spread over a quarter
    of the cell in x and y, and whether they are themselves a level patch (a ramp crosses a
    level plane in a band that would otherwise pass, voxel after voxel along its contour)."""
    min_spread = 0.25 * np.asarray(params.plane_voxel[:2])
    cnt = np.maximum(n_in, 1)
    mean_in = [sums[:, a] / cnt for a in range(3)]
    # The inliers' covariance entries as columns, in OUTER_INDEX order.
    _, n_in_plane = sym3_eigen_entries(
        *(outer[:, k] / cnt - mean_in[a] * mean_in[b] for k, (a, b) in enumerate(OUTER_INDEX))
    )
    level = np.abs(n_in_plane[:, 2]) >= np.cos(np.radians(params.max_tilt_deg))
    return np.all(hi - lo >= min_spread, axis=1), level


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
    if not (surface_of_voxel >= 0).any():
        return vet
    smooth = _smooth(surface_of_voxel, planes, params)
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
    # Grid cells about twice the k-th neighbour distance of the support's density (points
    # over its voxels' columns, spread as a surface): the exact search's quickest cells.
    density = len(support) / (len(vox) * float(grid.size[0] * grid.size[1]))
    normal, _ = normals_among(support, support[query], k, 2.0 * np.sqrt(k / (np.pi * density)))
    tilted = np.abs(normal[:, 2]) < np.cos(np.radians(params.normal_filter_max_tilt_deg))
    sorted_labels[pos[query[tilted]]] = -1
    return int(tilted.sum())
