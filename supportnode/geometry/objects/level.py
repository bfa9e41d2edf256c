"""Points at a surface's own level: set aside while objects are segmented, then given back.

A lidar's or a sampled cloud's table points beside an object's foot fall in voxels the table's
region growing leaves out (the object's points share them), so they reach the objects stage as
candidates. Left in, they chain two objects together through the 3 cm voxels and widen every
footprint by a skirt that fills the gap a footprint split would cut. They are taken out of the
candidates before clustering and splitting (:func:`set_aside`) and each is handed afterwards
to the object of its nearest object point (:func:`nearest_object_point`): it joins an object,
never links two.

Only surfaces without a measured noise band: a depth camera's surfaces label their band
themselves, and the objects' feet there are claimed by `feet.claim_feet`.
Points (M, 3) float64 metres, z up.
"""

from __future__ import annotations

import copy

import numpy as np

from supportnode.geometry.nearest import nearest_within
from supportnode.geometry.objects.support_lookup import _SupportLookup
from supportnode.geometry.surfaces import Surface
from supportnode.kernels.footprint import fill_holes, label8
from supportnode.kernels.lookup import level_points, level_split

# Points this close to a surface's fitted plane are at its level, metres. Fixed, not scaled
# with the surface's measured flatness: under 1 cm noise a band of one flatness took the
# bottoms of the objects too and cost the noisy rows 0.01-0.04 object ARI.
LEVEL = 0.003


# A surface's region growing stops short of its own board where a strip of it lies between
# two things (a box and a shelf's side) narrower than two of its voxels. The cells holding
# candidates at the surface's level (within LEVEL of its plane) joined to its footprint
# through such cells are its footprint too; looked for within this of the footprint's
# raster, metres.
BEYOND = 1.0


def extend_lookups(
    cp: np.ndarray,
    lookups: tuple[list[_SupportLookup], list[_SupportLookup]],
    surfaces: list[Surface],
) -> tuple[list[_SupportLookup], list[_SupportLookup]]:
    """The surfaces' lookups (undilated; dilated by one cell, whose ring holds what rises
    from a surface's height: see ``support_lookup._support_below``), the rings of those
    without a noise band grown along their level (see BEYOND) and hole-filled: the board runs
    on under the stack whose far side its growth missed, so the whole stack stands on it and
    the board's strip there is set aside with its level points instead of linking the stack
    to the shelf's side. cp: (M, 3) the candidates."""
    planes = _planes(surfaces)
    if planes is None or len(cp) == 0:
        return lookups
    rows, surf = level_points(cp, planes, LEVEL)
    if len(rows) == 0:
        return lookups
    order = np.argsort(surf, kind="stable")
    rows, surf = rows[order], surf[order]
    bounds = np.searchsorted(surf, np.arange(len(planes) + 1))
    dilated = list(lookups[1])
    for k, lk in enumerate(lookups[0]):
        a, b = (int(v) for v in bounds[lk.id : lk.id + 2]) if lk.id < len(planes) else (0, 0)
        if a == b:
            continue
        grown = _grown(lk, np.take(cp, rows[a:b], axis=0)[:, :2], BEYOND)
        if grown is not None:
            dilated[k] = _union(dilated[k], grown)
    return list(lookups[0]), dilated


def _union(a: _SupportLookup, b: _SupportLookup) -> _SupportLookup:
    """a's lookup over the union of a's and b's footprints (same cell size)."""
    lo = np.minimum(a.origin, b.origin)
    hi = np.maximum(a.origin + a.mask.shape, b.origin + b.mask.shape)
    mask = np.zeros(tuple(hi - lo), bool)
    for lk in (a, b):
        i, j = lk.origin - lo
        mask[i : i + lk.mask.shape[0], j : j + lk.mask.shape[1]] |= lk.mask
    out = copy.copy(a)
    out.mask, out.origin = mask, lo
    return out


def _grown(lk: _SupportLookup, xy: np.ndarray, reach: float) -> _SupportLookup | None:
    """lk with its footprint joined by the cells of the points xy (P, 2) that connect to it
    through cells holding such points (8-connected, within ``reach`` metres of its raster),
    holes filled; None when none does."""
    r = np.ceil(reach / lk.cell).astype(np.int64)
    h, w = lk.mask.shape
    ij = np.floor(xy / lk.cell).astype(np.int64) - (lk.origin - r)
    shape = np.array([h, w]) + 2 * r
    inside = np.all((ij >= 0) & (ij < shape), axis=1)
    mask = np.zeros(tuple(shape), bool)
    mask[r[0] : r[0] + h, r[1] : r[1] + w] = lk.mask
    grid = mask.copy()
    grid[ij[inside, 0], ij[inside, 1]] = True
    comp, _ = label8(grid)
    keep = np.zeros(int(comp.max()) + 1, bool)
    keep[comp[mask]] = True
    keep[0] = False
    joined = keep[comp]
    if not (joined & ~mask).any():
        return None
    out = copy.copy(lk)
    out.mask = fill_holes(joined)
    out.origin = lk.origin - r
    return out


def _planes(surfaces: list[Surface]) -> np.ndarray | None:
    """(S, 5) the surfaces' fitted planes by id, as `kernels.lookup.level_split` takes
    them, NaN rows for surfaces with a noise band (and ids of none); None when no surface is
    left."""
    planes = np.full((max((s.id for s in surfaces), default=-1) + 1, 5), np.nan)
    for s in surfaces:
        if s.band[0] > 0 or s.normal[2] <= 0:
            continue
        c, n = s.centroid, s.normal
        planes[s.id] = c[0], c[1], c[2], -n[0] / n[2], -n[1] / n[2]
    return planes if np.isfinite(planes).any() else None


def set_aside(
    cand: np.ndarray,
    cp: np.ndarray,
    support: np.ndarray,
    surfaces: list[Surface],
    reach: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The candidates (rows cand (M,), points cp (M, 3), support (M,): the surface under
    each) less those at their surface's level. Returns the rest's rows, points and supports,
    the positions (B,) among them of the objects' bottoms (within ``reach`` m above a
    level: where the level points look for their object), and the level points' rows (L,)."""
    planes = _planes(surfaces)
    if planes is None:  # no surface without a band: nothing to set aside
        none = np.zeros(0, np.int64)
        return cand, cp, support, none, none
    kept, kept_cp, kept_support, low, at = level_split(cp, cand, support, planes, LEVEL, reach)
    return kept, kept_cp, kept_support, low, np.take(cand, at)


def nearest_object_point(xyz: np.ndarray, obj_xyz: np.ndarray, reach: float) -> np.ndarray:
    """(K,) int64 for each level point xyz (K, 3), the row of the nearest object point of
    obj_xyz (M, 3) within ``reach`` metres, else -1: the level point goes wherever that
    point goes, splits included."""
    if len(xyz) == 0 or len(obj_xyz) == 0:
        return np.full(len(xyz), -1, dtype=np.int64)
    return nearest_within(obj_xyz, xyz, reach)[1]


def nearest_bottom(
    xyz: np.ndarray, cp: np.ndarray, lab: np.ndarray, bottom: np.ndarray, reach: float
) -> np.ndarray:
    """(K,) int64 for each level point xyz (K, 3) the row in cp (M, 3) of its nearest object
    point (lab (M,) >= 0) among the bottoms (rows (B,) from `set_aside`) within ``reach``
    metres, -1 for none."""
    if len(xyz) == 0:
        return np.zeros(0, np.int64)
    bottom = bottom[lab[bottom] >= 0]
    near = nearest_object_point(xyz, np.take(cp, bottom, axis=0), reach)
    near[near >= 0] = bottom[near[near >= 0]]
    return near
