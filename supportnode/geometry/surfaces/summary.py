"""Per-surface properties from its points (centroid, plane, height, area, cells)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from supportnode.geometry.linalg import sym3_eigen
from supportnode.geometry.surfaces.footprint import _cells_key, footprint_widths
from supportnode.geometry.surfaces.result import Surface
from supportnode.geometry.voxels import OUTER_INDEX, VoxelGrid
from supportnode.params import SurfaceParams


class _Runs(NamedTuple):
    """Runs of points of one (voxel, surface), the unit the surfaces' sums are taken over.

    g: (R,) surface index; vox: (R,) voxel index; n: (R,) points; corner: (R, 3) m, the voxel's
    corner; sum (R, 3), outer (R, 6): moments relative to the corner (``OUTER_INDEX`` order);
    lo, hi: (R, 3) m, the run's extremes."""

    g: np.ndarray
    vox: np.ndarray
    n: np.ndarray
    corner: np.ndarray
    sum: np.ndarray
    outer: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


class _Moments(NamedTuple):
    """Per surface (S,): point count (float), centroid (S, 3), upward unit normal (S, 3),
    flatness (rms distance to the plane, m), box (S, 3) and median height (m)."""

    counts: np.ndarray
    centroid: np.ndarray
    normal: np.ndarray
    flatness: np.ndarray
    bmin: np.ndarray
    bmax: np.ndarray
    height: np.ndarray


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
    # Imported here: importing the geometry (as the wire's types do) must not load numba.
    from supportnode.kernels.runs import label_runs

    # One compiled pass: which voxels are pure, the points per component, the mixed runs.
    pure, present, *mixed = label_runs(sorted_labels, grid.starts, grid.counts)
    if len(present) == 0:
        return [], np.full(1, -1, dtype=np.int32)
    comps = np.flatnonzero(present)
    s_count = len(comps)
    remap = np.full(len(present) + 1, -1, dtype=np.int64)  # last entry maps -1 to -1
    remap[comps] = np.arange(s_count)
    runs = _runs(grid, sorted_labels, np.flatnonzero(pure), mixed, remap)
    mom = _moments(runs, s_count)
    counts = mom.counts.astype(np.int64)
    vcount = np.bincount(remap[surface_of_voxel[surface_of_voxel >= 0]], minlength=s_count)
    vx, vy = float(params.plane_voxel[0]), float(params.plane_voxel[1])
    area, cells_of = _footprint_areas(
        grid.keys[runs.vox, :2], runs.g, runs.lo[:, :2], runs.hi[:, :2], runs.n, s_count, (vx, vy)
    )

    rank = np.lexsort((mom.centroid[:, 1], mom.centroid[:, 0], mom.height, -counts, -area))
    new_id = np.empty(s_count, dtype=np.int64)
    new_id[rank] = np.arange(s_count)
    width = _widths(cells_of, widths, (vx, vy))
    surfaces = []
    for sid, c in enumerate(rank):  # one entry per surface
        surfaces.append(
            Surface(
                id=sid,
                height=float(mom.height[c]),
                area=float(area[c]),
                centroid=mom.centroid[c],
                normal=mom.normal[c],
                flatness=float(mom.flatness[c]),
                bbox_min=mom.bmin[c],
                bbox_max=mom.bmax[c],
                outline=[],  # traced once the surface is kept (detect_surfaces)
                point_count=int(counts[c]),
                voxel_count=int(vcount[c]),
                cells=cells_of[c],
                cell_size=(vx, vy),
                width=float(width[c]),
            )
        )
    new_id = np.append(new_id, -1).astype(np.int32)
    return surfaces, new_id[remap]


def _widths(
    cells_of: list[np.ndarray], known: dict[bytes, float] | None, cell_size: tuple[float, float]
) -> np.ndarray:
    """The footprint width (m) of each footprint's cells, reusing those ``known`` by key."""
    width = np.array([-1.0 if known is None else known.get(_cells_key(c), -1.0) for c in cells_of])
    todo = np.flatnonzero(width < 0)
    if len(todo):
        width[todo] = footprint_widths([cells_of[i] for i in todo], cell_size)
    return width


def _runs(
    grid: VoxelGrid,
    sorted_labels: np.ndarray,
    pure_vox: np.ndarray,
    mixed: list[np.ndarray],
    remap: np.ndarray,
) -> _Runs:
    """The runs of one (voxel, surface) of the labelled points.

    Most surface voxels hold points of one surface only (``pure_vox``: all their points
    labelled, with one surface): their run is the whole voxel, whose moments the grid already
    has. Only mixed voxels are reduced point by point: ``mixed`` as `kernels.runs.label_runs`
    gives them (their labelled points' positions, runs into those, the runs' labels and
    voxels). Pure voxels' runs come first, then the mixed runs."""
    from supportnode.kernels.runs import range_extremes, run_moments

    idx, run, run_lab, run_vox = mixed
    # The mixed runs' moments and extremes read in place (compiled: no gathered columns).
    m_sum, m_outer, m_min, m_max = run_moments(grid.local, idx, run)
    vox = np.concatenate([pure_vox, run_vox])
    corner = grid.keys[vox] * grid.size
    # Extremes of the pure voxels from their own points (all of the voxel's).
    v_min, v_max = range_extremes(grid.local, grid.starts[pure_vox], grid.counts[pure_vox])
    return _Runs(
        g=np.concatenate([remap[sorted_labels[grid.starts[pure_vox]]], remap[run_lab]]),
        vox=vox,
        n=np.concatenate([grid.counts[pure_vox], np.diff(np.append(run, len(idx)))]),
        corner=corner,
        sum=np.concatenate([grid.sums[pure_vox], m_sum]),
        outer=np.concatenate([grid.outer[pure_vox], m_outer]),
        lo=np.concatenate([v_min, m_min]) + corner,
        hi=np.concatenate([v_max, m_max]) + corner,
    )


def _moments(runs: _Runs, s_count: int) -> _Moments:
    """Each surface's sums over its runs: count, centroid, plane, flatness, box, height."""
    run_g, run_n, corner, r_sum = runs.g, runs.n, runs.corner, runs.sum
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
            runs.outer[:, col]
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
    np.minimum.at(bmin, run_g, runs.lo)
    np.maximum.at(bmax, run_g, runs.hi)
    # Height: the median of z, taken over runs weighted by their points (a run is one voxel's
    # share of a level surface, so its mean z stands for its points to within the roughness).
    height = _weighted_median(abs_sum[:, 2] / run_n, run_n, run_g, s_count)
    return _Moments(counts, centroid, normal, flatness, bmin, bmax, height)


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
