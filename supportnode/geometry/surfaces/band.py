"""The noise band of a surface: which points lie on it, judged by the sensor's noise.

A fixed tolerance is wrong both ways on a depth camera: 1 cm keeps the bottom centimetre of
every object on the table (2-5 % of an object's points) and a bowl's inner bottom, while far
from the camera the table's own noise outgrows it. Each surface measures its noise instead:
the spread of its points about their voxels' planes, by range from the sensor, fitted as
``sigma(r)^2 = a^2 + (b r^2)^2`` (a depth camera's error grows with the square of the range;
``b = 0`` without a sensor). A point is on the surface within ``k sigma(r)`` of its plane,
never closer than ``band_min`` nor farther than the growth's tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.geometry.linalg import distances, sym3_eigen_entries
from supportnode.geometry.surfaces.groups import columns_per_group
from supportnode.geometry.surfaces.noise import NoiseModel, fit_sample
from supportnode.geometry.surfaces.planar import (
    _label_by_plane_of,
    _label_points_planar,
    _plane_in,
    _Planes,
)
from supportnode.geometry.voxels import OUTER_INDEX, KeyIndex, Labelled, VoxelGrid
from supportnode.kernels.components import label_edges
from supportnode.params import SurfaceParams

# A patch of a surface's band whose columns average this many sigma above the plane, over
# at least this area (m^2), is no part of it (see drop_raised).
_RAISED_SIGMAS = 1.5
_RAISED_MIN_AREA = 0.004


@dataclass(frozen=True)
class Band:
    """Each surface's band: ``width(surface, voxel)`` (K,) metres for surface components
    (K,) and the grid's voxels (K,) holding the points: ``sigmas`` noise sigmas at the
    voxels' range, at least ``floor``, for the components the band decides (``by_band``,
    (C,)), at most ``tolerance``; the growth's ``tolerance`` (C,) for the others."""

    model: NoiseModel
    sigmas: float
    floor: float
    r_voxel: np.ndarray | None  # (M,) range of each voxel's centre from the sensor, m
    by_band: np.ndarray
    tolerance: np.ndarray

    def width(self, surface: np.ndarray, voxel: np.ndarray) -> np.ndarray:
        r = 0.0 if self.r_voxel is None else self.r_voxel[voxel]
        w = np.maximum(self.sigmas * self.model.sigma(surface, r), self.floor)
        return np.where(
            self.by_band[surface], np.minimum(w, self.tolerance[surface]), self.tolerance[surface]
        )


def label_in_band(
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    tolerance: np.ndarray,
    sensor_origin: np.ndarray | None,
    params: SurfaceParams,
) -> tuple[np.ndarray, np.ndarray, Band | None]:
    """Surface labels in the grid's voxel order (as ``_label_points_planar``), the points'
    heights above their planes, metres, and the surfaces' band (by surface component; None
    when ``params.band_sigmas`` is 0: ``tolerance`` alone).

    The points within the growth's ``tolerance`` (per component) measure each surface's
    noise. Where the band decides (:func:`band_decides`: a depth camera's surfaces), the
    noise is measured again about planes refitted over each voxel's neighbours (which the
    voxels holding clutter keep), and the labels redone within ``params.band_sigmas`` sigma
    at the range of each point's voxel, at least ``params.band_min``, at most ``tolerance``;
    elsewhere ``tolerance`` stays. ``planes`` may
    change."""
    labels, best = _label_points_planar(grid, index, surface_of_voxel, planes, tolerance)
    if params.band_sigmas <= 0 or not (labels >= 0).any():
        return labels, best, None
    r_voxel = None
    if sensor_origin is not None:
        centre = (grid.keys + 0.5) * grid.size
        r_voxel = distances(centre, sensor_origin)
    # The labelled points found once for the steps that read these labels.
    lab = grid.labelled(labels)
    model = fit_sample(grid, labels, best, r_voxel, len(tolerance), lab)
    none = np.zeros(len(tolerance), dtype=bool)
    band = Band(model, params.band_sigmas, params.band_min, r_voxel, none, tolerance)
    by_band = band_decides(grid, labels, surface_of_voxel, band, params.clutter_normal_k, lab)
    if not by_band.any():
        return labels, best, band
    # The noise is measured about the windows' planes (a surface straddling two layers of
    # voxels fits each half its own plane, and its noise looks halved); those planes replace
    # the voxels' own where clutter stands in the column (a foot tilts the plane) or the
    # voxel's own plane leaves its window's by more than the noise (a pot's inner bottom
    # lifts it): elsewhere a voxel's own plane follows the surface, and a far depth camera's
    # steps, best.
    window = _Planes(planes.mean.copy(), planes.normal.copy(), planes.roughness)
    refit_planes(grid, index, surface_of_voxel, window, labels, by_band, lab)
    trial, best = _label_points_planar(grid, index, surface_of_voxel, window, tolerance)
    model = fit_sample(grid, trial, best, r_voxel, len(tolerance), grid.labelled(trial))
    sv = np.flatnonzero(surface_of_voxel >= 0)
    sv = sv[by_band[surface_of_voxel[sv]]]
    r = 0.0 if r_voxel is None else r_voxel[sv]
    off = _miss(grid, planes, window, sv) > _OFF_SIGMAS * model.sigma(surface_of_voxel[sv], r)
    take = np.union1d(_cluttered(grid, index, surface_of_voxel, lab), sv[off])
    planes.mean[take] = window.mean[take]
    planes.normal[take] = window.normal[take]
    band = Band(model, params.band_sigmas, params.band_min, r_voxel, by_band, tolerance)
    labels, best = _label_points_planar(
        grid, index, surface_of_voxel, planes, tolerance, band.width
    )
    return labels, best, band


# The voxels beside a surface voxel (and a layer up or down) that the ring pass labels.
_RING = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if x or y]


def label_ring(
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    kept: np.ndarray,
    planes: _Planes,
    labels: np.ndarray,
    best: np.ndarray,
    band: Band,
) -> np.ndarray:
    """Label, in place, points of the voxels around the kept surfaces' voxels that are no
    kept surface's voxel themselves, within the band of the neighbouring surface voxel's plane (the
    nearest plane wins): a surface's cluttered columns that growth left out (a can's foot
    beside the table leaves the table around it unlabelled otherwise). kept: (C,) bool per
    surface component. Returns (C,) the points added per component."""
    sv = np.flatnonzero(surface_of_voxel >= 0)
    sv = sv[kept[surface_of_voxel[sv]]]
    before = labels.copy()
    hit = index.neighbours_many(sv, _RING, grid.keys)  # (offsets, sv)
    on = hit >= 0
    other = surface_of_voxel[hit[on]]
    on[on] = (other < 0) | ~kept[np.maximum(other, 0)]
    # Every offset's runs in one call, offset after offset (row-major order): the kernel
    # applies runs in order, as the calls offset by offset did.
    vsel, t = hit[on], np.broadcast_to(sv, hit.shape)[on]
    if len(vsel):
        surf = surface_of_voxel[t]
        _label_by_plane_of(grid, planes, t, vsel, surf, band.width(surf, vsel), labels, best, True)
    # Only the voxels labelled in can hold new labels: counted there (compiled), not over all.
    from supportnode.kernels.runs import newly_labelled

    touched = np.unique(vsel)
    return newly_labelled(labels, before, grid.starts[touched], grid.counts[touched], len(kept))


# A voxel's own plane leaving its window's by more than this many noise sigmas is not the
# surface's (see label_in_band).
_OFF_SIGMAS = 2.0


def _miss(grid: VoxelGrid, own: _Planes, window: _Planes, sv: np.ndarray) -> np.ndarray:
    """(K,) the largest height difference of two planes of the voxels ``sv`` over each
    voxel's x, y square, metres."""
    a0, bx0, by0 = _plane_in(grid, own.mean[sv], own.normal[sv], sv)
    a1, bx1, by1 = _plane_in(grid, window.mean[sv], window.normal[sv], sv)
    miss = np.zeros(len(sv))
    for cx in (0.0, grid.size[0]):
        for cy in (0.0, grid.size[1]):
            miss = np.maximum(miss, np.abs((a0 - a1) + (bx0 - bx1) * cx + (by0 - by1) * cy))
    return miss


# A surface voxel holds clutter when this share of the points in it and in the voxel above
# it are on no surface.
_CLUTTER_SHARE = 0.05


def _cluttered(
    grid: VoxelGrid, index: KeyIndex, surface_of_voxel: np.ndarray, lab: Labelled
) -> np.ndarray:
    """The surface voxels (indices) holding clutter, in them or just above them. lab: the
    grid's labelled points (`VoxelGrid.labelled`)."""
    sv = np.flatnonzero(surface_of_voxel >= 0)
    off = grid.counts - lab.per if len(grid.order) else None  # unlabelled points per voxel
    if off is None or len(sv) == 0:
        return np.zeros(0, np.int64)
    (up,) = index.neighbours_many(sv, [(0, 0, 1)], grid.keys)
    loose = off[sv] + np.where(up >= 0, off[np.maximum(up, 0)], 0)
    total = grid.counts[sv] + np.where(up >= 0, grid.counts[np.maximum(up, 0)], 0)
    return sv[loose >= _CLUTTER_SHARE * total]


# The window of voxels whose inliers refit a surface voxel's plane (3 x 3 columns, +-1 layer).
_WINDOW = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)]


def refit_planes(
    grid: VoxelGrid,
    index: KeyIndex,
    surface_of_voxel: np.ndarray,
    planes: _Planes,
    labels: np.ndarray,
    which: np.ndarray,
    lab: Labelled | None = None,
) -> None:
    """Refit, in place, each surface voxel's plane to the labelled points of its surface in
    the voxels around it (3 x 3 columns): a voxel holding an object's foot fits a plane
    tilted toward it, which a narrow band then misses on the table side; its neighbours'
    inliers outvote the foot. labels: (N,) surface component per point in the grid's voxel
    order, -1 for none; which: (C,) bool, the components refitted; lab: its labelled points
    (`VoxelGrid.labelled`) when known."""
    sv = np.flatnonzero(surface_of_voxel >= 0)
    sv = sv[which[surface_of_voxel[sv]]]
    lab = grid.labelled(labels) if lab is None else lab
    if len(sv) == 0 or len(lab.at) == 0:
        return
    count, s1, s2, lab_of_voxel = _labelled_moments(grid, lab)
    own = surface_of_voxel[sv]
    j = index.neighbours_many(sv, _WINDOW, grid.keys)  # (window, sv)
    ok = j >= 0
    ok[ok] = lab_of_voxel[j[ok]] == np.broadcast_to(own, j.shape)[ok]
    jj = np.where(ok, j, 0)
    w = np.where(ok, 1.0, 0.0)
    # Each sum over the window from 0, voxel after voxel (accumulate: never numpy's
    # pairwise order), all offsets at once rather than a dozen calls per offset.
    start = np.zeros((1, len(sv)))

    def window_sum(per_voxel: np.ndarray) -> np.ndarray:
        return np.add.accumulate(np.concatenate([start, w * per_voxel[jj]]), axis=0)[-1]

    c = window_sum(count)
    t1 = [window_sum(s1[a]) for a in range(3)]
    t2 = [window_sum(s2[k]) for k in range(6)]
    fit = c >= 3
    mean = [t1[a][fit] / c[fit] for a in range(3)]
    entries = [t2[k][fit] / c[fit] - mean[a] * mean[b] for k, (a, b) in enumerate(OUTER_INDEX)]
    _, normal = sym3_eigen_entries(*entries)
    normal = np.where(normal[:, 2:3] < 0, -normal, normal)
    level = normal[:, 2] > 0.5  # a degenerate window keeps its voxel's own plane
    to = sv[fit][level]
    new_mean, new_normal = np.stack(mean, axis=1)[level], normal[level]
    planes.mean[to] = new_mean
    planes.normal[to] = new_normal


def _labelled_moments(
    grid: VoxelGrid, lab: Labelled
) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Per voxel (V,): the count, the sums (3 columns) and the sums of products (6, in
    ``OUTER_INDEX`` order) of its labelled points ``lab`` (`VoxelGrid.labelled`) about the
    grid's origin, metres; and the surface label of its labelled points (-1: none)."""
    from supportnode.kernels.runs import run_moments

    n_vox = len(grid.counts)
    # One compiled pass over runs of the grid's columns, about each voxel's corner, then
    # shifted to the grid's origin. A voxel's labelled points come in one run.
    v = np.flatnonzero(lab.per)
    run = (np.cumsum(lab.per) - lab.per)[v]
    loc1, loc2, _, _ = run_moments(grid.local, lab.at, run)
    n = lab.per[v].astype(np.float64)
    corner = grid.keys[v] * grid.size
    count = np.zeros(n_vox)
    count[v] = n
    s1 = [np.zeros(n_vox) for _ in range(3)]
    for a in range(3):
        s1[a][v] = loc1[:, a] + n * corner[:, a]
    s2 = [np.zeros(n_vox) for _ in range(6)]
    for q, (a, b) in enumerate(OUTER_INDEX):
        s2[q][v] = (
            loc2[:, q]
            + corner[:, a] * loc1[:, b]
            + corner[:, b] * loc1[:, a]
            + n * corner[:, a] * corner[:, b]
        )
    # Each voxel's last labelled point's label (as assigning all of them, the last winning,
    # did: ten times the time).
    return count, s1, s2, lab.last


def drop_raised(
    grid: VoxelGrid, labels: np.ndarray, best: np.ndarray, band: Band, cell: float
) -> np.ndarray:
    """Unlabel, in place, the points of raised patches of a surface's band: columns about
    ``cell`` wide whose points lie on average more than ``_RAISED_SIGMAS`` sigma above their
    plane, joined into patches of at least ``_RAISED_MIN_AREA`` m^2. The table's own points
    average zero; a pot's inner bottom a few millimetres above it (or a sheet lying on it)
    does not, though each of its points is within the band. Only surfaces the band decides.
    Returns the positions (grid order) unlabelled."""
    none = np.zeros(0, np.int64)
    if not band.by_band.any():
        return none
    # Imported here: only a depth camera's surfaces are labelled by their band, and
    # `runtime.warm` loads the kernels of every imported kernel module (~4 ms each).
    from supportnode.kernels.band import column_sums, points_in_columns

    # Columns within each voxel (a whole number of them per voxel edge): grouped without a
    # sort, by the voxel and the column's place in it.
    per = np.maximum(np.round(grid.size[:2] / cell).astype(np.int64), 1)
    cols = (grid.starts, grid.counts, grid.local, grid.size, labels, band.by_band)
    n, total, comp = column_sums(*cols, best, per)
    n_keys = len(n)
    mean = total / np.maximum(n, 1)
    r = np.zeros(len(comp)) if band.r_voxel is None else band.r_voxel
    sigma = band.model.sigma(np.maximum(comp, 0), r)[np.arange(n_keys) // (per[0] * per[1])]
    raised = np.flatnonzero(
        (n >= 4) & (mean > np.maximum(_RAISED_SIGMAS * sigma, 0.5 * band.floor))
    )
    if len(raised) == 0:
        return none
    # 8-connected patches of raised columns, by their global column and surface.
    v = raised // (per[0] * per[1])
    gi = grid.keys[v, 0] * per[0] + (raised // per[1]) % per[0]
    gj = grid.keys[v, 1] * per[1] + raised % per[1]
    gi, gj = gi - gi.min() + 1, gj - gj.min() + 1
    span = int(gj.max()) + 2
    rk = (comp[v] * (int(gi.max()) + 2) + gi) * span + gj
    order = np.argsort(rk)
    rk = rk[order]
    src, dst = [], []
    for st in (1, span - 1, span, span + 1):
        hit = np.searchsorted(rk, rk + st)
        ok = (hit < len(rk)) & (rk[np.minimum(hit, len(rk) - 1)] == rk + st)
        src.append(np.flatnonzero(ok))
        dst.append(hit[ok])
    patch = label_edges(len(rk), np.concatenate(src), np.concatenate(dst))
    area = np.bincount(patch) * float(np.prod(grid.size[:2] / per))
    big = np.zeros(n_keys, bool)
    big[raised[order][area[patch] >= _RAISED_MIN_AREA]] = True
    gone = points_in_columns(*cols, big, per)
    labels[gone] = -1
    return gone


# k-NN normals vet a surface's points (the clutter test) only where the neighbourhood of
# clutter_normal_k points is this many noise sigmas wide: on a dense, noisy depth image ten
# neighbours span a few millimetres, and their normals scatter like the noise.
_VET_MIN_SIGMAS = 8.0


def band_decides(
    grid: VoxelGrid,
    labels: np.ndarray,
    surface_of_voxel: np.ndarray,
    band: Band,
    k: int,
    lab: Labelled | None = None,
) -> np.ndarray:
    """(C,) bool per surface component: the noise band, not k-NN normals, decides which of
    its points are on it (a depth camera's surfaces). There the points' k-NN normals say
    nothing about tilt (their neighbourhood, ~ spacing sqrt(k / pi) wide, is under
    ``_VET_MIN_SIGMAS`` sigma), while the band is thin against an object (at most a quarter
    of a voxel's height): the objects' feet are told apart by where the objects stand. On a
    cloud noisy beyond that (a slab as thick as the objects are tall), neither tells.
    lab: the labelled points of ``labels`` (`VoxelGrid.labelled`) when known."""
    from supportnode.kernels.band import label_voxel_counts  # a depth camera's kernels

    n_comp = len(band.model.a)
    lab = grid.labelled(labels) if lab is None else lab
    at, n_vox = lab.at, len(grid.counts)
    # The same sorted keys and counts as np.unique, without its sort, when dense enough.
    dense = band.r_voxel is not None and n_comp * n_vox <= 4 * len(at) + (1 << 16)
    counted = label_voxel_counts(labels, at, lab.vox, n_comp, n_vox, dense)
    comp = None
    if counted is None:  # a label past n_comp: numpy's counts, however long
        comp = labels[at].astype(np.int64)
        count = np.bincount(comp, minlength=n_comp).astype(np.float64)
    else:
        count = counted[0].astype(np.float64)
    area = columns_per_group(surface_of_voxel, grid.keys, n_comp) * grid.size[0] * grid.size[1]
    spacing = np.sqrt(area / np.maximum(count, 1.0))
    # Each component's median range, from its voxels weighted by their labelled points.
    r_med = np.zeros(n_comp)
    if band.r_voxel is not None:
        if dense and counted is not None:
            w = counted[1]
            key = np.flatnonzero(w)
            w = w[key]
        else:
            comp = labels[at].astype(np.int64) if comp is None else comp
            flat = comp * n_vox + lab.vox
            if n_comp * n_vox <= 4 * len(flat) + (1 << 16):
                w = np.bincount(flat, minlength=n_comp * n_vox)
                key = np.flatnonzero(w)
                w = w[key]
            else:
                key, w = np.unique(flat, return_counts=True)
        c, r = key // n_vox, band.r_voxel[key % n_vox]
        order = np.lexsort((r, c))
        cw = np.cumsum(w[order])
        first = np.searchsorted(c[order], np.arange(n_comp))
        half = np.r_[0, cw][first] + count / 2.0
        r_med = r[order][np.minimum(np.searchsorted(cw, half), len(order) - 1)]
    sigma = band.model.sigma(np.arange(n_comp), r_med)
    thin = band.sigmas * sigma <= 0.25 * grid.size[2]
    return (count > 0) & thin & (spacing * np.sqrt(k / np.pi) < _VET_MIN_SIGMAS * sigma)
