"""The entry point: :func:`detect_surfaces` runs the seed or the planar method."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.errors import InputError
from supportnode.geometry.surfaces.band import Band, drop_raised, label_in_band, label_ring
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
    _Planes,
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
    planar: _PlanarState | None = None
    if params.method == "seed":
        surface_of_voxel, stats = _grow_seed(grid, params)
        sorted_labels = np.repeat(surface_of_voxel, grid.counts)
    elif params.method == "planar":
        widths = {}
        surface_of_voxel, sorted_labels, stats, planar = _label_planar(
            grid, params, widths, sensor_origin
        )
    else:
        raise InputError(f"unknown surface method '{params.method}' (expected seed or planar)")
    # Surface ids by the points' labels so far (lut[label], -1 for -1): one gather of all
    # points at the end, not one a stage.
    surfaces, lut = _summarise(grid, sorted_labels, surface_of_voxel, params, widths)
    if planar is not None:
        surfaces, lut = _drop_unfit(grid, surfaces, sorted_labels, lut, params, sensor_origin)
        if planar.band is not None and surfaces:
            _fill_ring(grid, surface_of_voxel, sorted_labels, lut, surfaces, planar)
            _note_noise(surfaces, planar.band, lut)
    # Outlines only of the surfaces kept, all traced together.
    cell_size = (float(params.plane_voxel[0]), float(params.plane_voxel[1]))
    outlines = cells_outlines([s.cells for s in surfaces], cell_size)
    for s, outline in zip(surfaces, outlines, strict=True):
        s.outline = outline
    from supportnode.kernels.runs import scatter_lookup  # numba only when used

    labels = np.full(len(pts), -1, dtype=np.int32)
    rows = grid.order if keep is None else np.flatnonzero(keep)[grid.order]
    scatter_lookup(labels, rows, lut.astype(np.int32, copy=False), sorted_labels)
    raised = np.zeros(0, np.int64) if planar is None else np.sort(rows[planar.raised])
    stats.update(points=len(pts), voxels=len(grid.counts), surfaces=len(surfaces))
    if keep is not None:
        stats["normal_filter_removed"] = int(len(pts) - keep.sum())
    return SurfaceResult(surfaces=surfaces, labels=labels, stats=stats, raised=raised)


@dataclass
class _PlanarState:
    """What the planar method's last steps (after the surfaces' summaries) continue from."""

    index: KeyIndex
    planes: _Planes
    best: np.ndarray  # (N,) each labelled point's height above its plane, grid order, m
    band: Band | None
    raised: np.ndarray  # positions (grid order) of raised patches taken out of the band


def _label_planar(
    grid: VoxelGrid,
    params: SurfaceParams,
    widths: dict[bytes, float],
    sensor_origin: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, dict, _PlanarState]:
    """The planar method's surface of each voxel, label of each point (grid order), stats,
    and the state its last steps need.

    Grows level voxels into surfaces, absorbs the clutter around them, joins the pieces they
    meet, applies the size limits (footprint widths measured go into ``widths``), cuts raised
    plateaus out and labels the points: within each surface's noise band where that decides
    (a depth camera's; raised patches of the band then leave it), else within its tolerance,
    the points admitted in cluttered voxels vetted by their normals."""
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
    sorted_labels, best, band = label_in_band(
        grid, index, surface_of_voxel, planes, tolerance, sensor_origin, params
    )
    raised = np.zeros(0, np.int64)
    if band is not None:
        stats["band_surfaces"] = int(band.by_band.sum())
        raised = drop_raised(grid, sorted_labels, best, band, _RAISED_CELL)
        stats["raised_points"] = len(raised)
    if params.clutter_normal_k > 0:
        vetted = _voxels_to_vet(grid, sorted_labels, surface_of_voxel, planes, absorbed, params)
        if band is not None:
            vetted = vetted[~band.by_band[surface_of_voxel[vetted].clip(0)]]
        stats["clutter_points_rejected"] = _reject_tilted_clutter(
            grid, index, sorted_labels, vetted, params
        )
    state = _PlanarState(index, planes, best, band, raised)
    return surface_of_voxel, sorted_labels, stats, state


# Columns of this width, metres, average a band's heights for raised patches (drop_raised).
_RAISED_CELL = 0.01


def _fill_ring(
    grid: VoxelGrid,
    surface_of_voxel: np.ndarray,
    sorted_labels: np.ndarray,
    lut: np.ndarray,
    surfaces: list,
    planar: _PlanarState,
) -> None:
    """The band's ring pass (:func:`label_ring`) for the surfaces kept whose points the band
    decides; their point counts follow. lut: component -> surface id (last entry: -1)."""
    band = planar.band
    assert band is not None
    n_comp = int(surface_of_voxel.max()) + 1
    m = min(n_comp, len(lut) - 1)
    kept = np.zeros(n_comp, dtype=bool)
    kept[:m] = lut[:m] >= 0
    kept &= band.by_band[:n_comp]
    if not kept.any():
        return
    added = label_ring(
        grid, planar.index, surface_of_voxel, kept, planar.planes, sorted_labels, planar.best, band
    )
    for comp in np.flatnonzero(added):
        surfaces[lut[comp]].point_count += int(added[comp])


def _note_noise(surfaces: list, band: Band, lut: np.ndarray) -> None:
    """Each surface's measured noise, and the band (or tolerance) that labelled it."""
    for comp in range(min(len(band.model.a), len(lut) - 1)):
        if lut[comp] >= 0:
            s = surfaces[lut[comp]]
            s.noise = (float(band.model.a[comp]), float(band.model.b[comp]))
            s.band = (
                (band.sigmas, band.floor)
                if band.by_band[comp]
                else (0.0, float(band.tolerance[comp]))
            )


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
