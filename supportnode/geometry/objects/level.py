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

import numpy as np
from scipy.spatial import cKDTree

from supportnode.geometry.surfaces import Surface
from supportnode.kernels.lookup import level_split

# Points this close to a surface's fitted plane are at its level, metres. Fixed, not scaled
# with the surface's measured flatness: under 1 cm noise a band of one flatness took the
# bottoms of the objects too and cost the noisy rows 0.01-0.04 object ARI.
LEVEL = 0.003


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
    out = np.full(len(xyz), -1, dtype=np.int64)
    if len(xyz) == 0 or len(obj_xyz) == 0:
        return out
    dist, k = cKDTree(obj_xyz).query(xyz, distance_upper_bound=reach)
    hit = np.isfinite(dist)
    out[hit] = k[hit]
    return out


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
