"""The entry point: :func:`detect_surfaces` runs the seed or the planar method."""

from __future__ import annotations

import numpy as np

from supportnode.errors import InputError
from supportnode.geometry.surfaces.clutter import (
    _absorb_clutter,
    _reject_tilted_clutter,
    _voxels_to_vet,
)
from supportnode.geometry.surfaces.filters import _drop_raised_plateaus, _drop_unfit
from supportnode.geometry.surfaces.footprint import cells_outlines
from supportnode.geometry.surfaces.groups import _components
from supportnode.geometry.surfaces.planar import (
    _connect,
    _filter_components,
    _grow_planar,
    _label_points_planar,
    _surface_tolerance,
)
from supportnode.geometry.surfaces.result import SurfaceResult
from supportnode.geometry.surfaces.summary import _summarise
from supportnode.geometry.voxels import KeyIndex, VoxelGrid, horizontal_offsets, voxelize
from supportnode.params import SurfaceParams


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
    size = np.asarray(params.plane_voxel, dtype=np.float64)
    keep = None
    if params.normal_filter and len(pts):
        keep = _normal_filter_mask(pts, params)
    used = pts if keep is None else pts[keep]
    grid = voxelize(used, size)
    # Point labels are kept in the grid's voxel order (contiguous per voxel) until the end.
    widths: dict[bytes, float] | None = None
    if params.method == "seed":
        surface_of_voxel, stats = _grow_seed(grid, params)
        sorted_labels = np.repeat(surface_of_voxel, grid.counts)
    elif params.method == "planar":
        widths = {}
        surface_of_voxel, sorted_labels, stats = _label_planar(grid, params, widths)
    else:
        raise InputError(f"unknown surface method '{params.method}' (expected seed or planar)")
    # Surface ids by the points' labels so far (lut[label], -1 for -1): one gather of all
    # points at the end, not one a stage.
    surfaces, lut = _summarise(grid, sorted_labels, surface_of_voxel, params, widths)
    if params.method == "planar":
        surfaces, lut = _drop_unfit(grid, surfaces, sorted_labels, lut, params, sensor_origin)
    # Outlines only of the surfaces kept, all traced together.
    cell_size = (float(params.plane_voxel[0]), float(params.plane_voxel[1]))
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


def _label_planar(
    grid: VoxelGrid, params: SurfaceParams, widths: dict[bytes, float]
) -> tuple[np.ndarray, np.ndarray, dict]:
    """The planar method's surface of each voxel, label of each point (grid order) and stats.

    Grows level voxels into surfaces, absorbs the clutter around them, joins the pieces they
    meet, applies the size limits (footprint widths measured go into ``widths``), cuts raised
    plateaus out and vets the points admitted in cluttered voxels by their normals."""
    index = KeyIndex.build(grid.keys)
    surface_of_voxel, planes, stats = _grow_planar(grid, index, params)
    tolerance = _surface_tolerance(surface_of_voxel, planes, params)
    absorbed = _absorb_clutter(grid, index, surface_of_voxel, planes, tolerance, params)
    stats["absorbed_voxels"] = len(absorbed)
    # Pieces of one board, split by the objects on it, meet once grown around them.
    sv = np.flatnonzero(surface_of_voxel >= 0)
    edges: list[np.ndarray] = []
    if len(sv):
        surface_of_voxel[sv] = _connect(
            grid, index, sv, planes.mean[sv], planes.normal[sv], params, edges=edges
        )
        tolerance = _surface_tolerance(surface_of_voxel, planes, params)
    # Size limits apply to what a surface became: a board seen between objects is a
    # narrow strip until it has grown under and around them.
    stats["rejected_narrow"] = _filter_components(grid, surface_of_voxel, params, widths)
    # A cutting board or a plate joins the worktop it lies on: cut it out again.
    stats["plateau_voxels"] = 0
    if edges:
        src, dst = edges  # the pairs of sv that _connect joined
        stats["plateau_voxels"] = _drop_raised_plateaus(
            grid, surface_of_voxel, planes, tolerance, sv, src, dst, params
        )
    sorted_labels = _label_points_planar(grid, index, surface_of_voxel, planes, tolerance)
    vetted = _voxels_to_vet(grid, sorted_labels, surface_of_voxel, planes, absorbed, params)
    stats["clutter_points_rejected"] = _reject_tilted_clutter(
        grid, index, sorted_labels, vetted, params
    )
    return surface_of_voxel, sorted_labels, stats


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

    grid = voxelize(pts, np.asarray(params.plane_voxel, dtype=np.float64))
    candidate = (grid.counts > params.p_min)[grid.point_voxel]
    return (
        filter_vertical_normals(
            pts, candidate, params.normal_filter_k, params.normal_filter_max_tilt_deg
        )
        | ~candidate
    )


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
