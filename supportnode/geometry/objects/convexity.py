"""Objects as faces joined by convex boundaries (local convexity, after LCCP: Stein et al., 2014).

Small patches (voxels with their moments and normals) are linked where their points touch
(fine cells 26-adjacent: a gap wider than a fine cell cuts), and a link is kept only where
the two patches meet convexly (normals diverging along the vector between the centroids) or
smoothly (a small angle between the normals: a bowl's concave inside stays whole); sharp
concave creases (a box on a box, two boxes face to face, a can against a box, an object on
its table) are cut. The segments are the connected components of the kept links. Works on
unorganised points (a merged map has no image grid). Pure: numpy in, labels out.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.linalg import sym3_eigen
from supportnode.geometry.objects.neighbours import FORWARD_26
from supportnode.kernels.components import label_edges

_MIN_PER_CELL = 3  # median points per occupied fine cell
_MAX_CELL = 0.04  # metres: the grid stops growing here (gaps of a few cm cut)


def convex_segments(
    points: np.ndarray,
    origin: np.ndarray | None,
    fine: float = 0.005,
    ratio: int = 2,
    smooth_deg: float = 25.0,
    convex_tol: float = 0.05,
    min_points: int = 30,
    crease_curvature: float = 20.0,
) -> np.ndarray:
    """(M,) int64 segment of each point of ``points`` (M, 3) float, metres; -1 for none.

    origin: (3,) sensor position (normals turn toward it), None: normals turn away from the
    points' centroid. fine: cell edge whose adjacency links points, metres (a gap wider than
    it cuts); ratio: patch edge in fine cells. smooth_deg: neighbouring patches whose normals
    differ by less than this stay linked even where they meet concavely. convex_tol: how far
    below zero the convexity measure ``(n_i - n_j) . d_ij / |d_ij|`` may fall for noise.
    Segments smaller than ``min_points`` join the neighbour they share the most links with.
    crease_curvature: 1/m; a patch hollow by more than this toward the sensor is a crease.
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) == 0:
        return np.zeros(0, np.int64)
    fine_of, fine_keys, dims = _cells(pts, fine)
    # Cells follow the point spacing: a sparse cloud (a sampled map, a far lidar return) has
    # too few points per cell for its surfaces to touch, so the cell grows until a typical
    # occupied cell holds a few points (a surface sampled at half the cell or finer).
    while np.median(np.bincount(fine_of)) < _MIN_PER_CELL and fine < _MAX_CELL:
        fine *= 1.5
        fine_of, fine_keys, dims = _cells(pts, fine)
    patch_of_fine = _patch_ids(fine_keys, dims, ratio)
    patch = patch_of_fine[fine_of]
    n_patch = int(patch_of_fine.max()) + 1
    src, dst = _patch_links(fine_keys, dims, patch_of_fine)
    centroid, normal, count = _moments(pts, patch, n_patch, src, dst)
    view = (pts.mean(axis=0) if origin is None else np.asarray(origin, np.float64)) - centroid
    flip = np.einsum("ij,ij->i", normal, view) < 0
    if origin is None:
        flip = ~flip  # away from the centroid
    normal[flip] *= -1.0
    keep = _keep_links(centroid, normal, src, dst, smooth_deg, convex_tol)
    # A patch straddling a concave crease has a normal between its two faces and links
    # "convexly" to both where the crease ends beside an occluded face: such patches link
    # nothing, and join a neighbouring segment afterwards.
    crease = _concavity(pts, patch, centroid, normal, count) > crease_curvature
    keep &= ~(crease[src] | crease[dst])
    comp = label_edges(n_patch, src[keep], dst[keep])
    size = np.bincount(comp, weights=count).astype(np.int64)
    small = size < min_points
    small[comp[crease]] = True
    comp = _absorb_small(comp, small, src, dst)
    return comp[patch]


def _concavity(
    pts: np.ndarray, patch: np.ndarray, centroid: np.ndarray, normal: np.ndarray, count: np.ndarray
) -> np.ndarray:
    """(P,) curvature of each patch toward its normal, 1/m (> 0: a hollow facing the sensor,
    as at a concave crease; ~0 on a face): the least-squares k of h = k r^2 / 2 over its
    points (h their height over the patch plane, r their distance from the centroid in it)."""
    n = len(count)
    off = pts - centroid[patch]
    h = np.einsum("ij,ij->i", off, normal[patch])
    r2 = np.einsum("ij,ij->i", off, off) - h * h
    mr2 = np.bincount(patch, r2, n) / count
    dr2 = r2 - mr2[patch]
    cov = np.bincount(patch, h * dr2, n)
    var = np.bincount(patch, dr2 * dr2, n)
    return np.where((count >= 6) & (var > 0), 2.0 * cov / np.where(var > 0, var, 1.0), 0.0)


def _cells(pts: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each point's fine cell (M,), the cells' packed keys (F,) sorted, and the grid's dims."""
    ijk = np.floor((pts - pts.min(axis=0)) / size).astype(np.int64) + 1  # 1-cell margin
    dims = ijk.max(axis=0) + 2
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    keys, inverse = np.unique(key, return_inverse=True)
    return inverse.reshape(-1), keys, dims


def _unpack(keys: np.ndarray, dims: np.ndarray) -> np.ndarray:
    z = keys % dims[2]
    y = (keys // dims[2]) % dims[1]
    return np.stack([keys // (dims[1] * dims[2]), y, z], axis=1)


def _patch_ids(fine_keys: np.ndarray, dims: np.ndarray, ratio: int) -> np.ndarray:
    """(F,) patch id of each fine cell: the coarse cell ``ratio`` fine cells wide holding it."""
    coarse = _unpack(fine_keys, dims) // ratio
    cdims = coarse.max(axis=0) + 1
    ckey = (coarse[:, 0] * cdims[1] + coarse[:, 1]) * cdims[2] + coarse[:, 2]
    return np.unique(ckey, return_inverse=True)[1].reshape(-1)


def _patch_links(
    fine_keys: np.ndarray, dims: np.ndarray, patch_of_fine: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Unique pairs (src < dst) of patches holding 26-adjacent occupied fine cells."""
    steps = (FORWARD_26[:, 0] * dims[1] + FORWARD_26[:, 1]) * dims[2] + FORWARD_26[:, 2]
    a_all, b_all = [], []
    for step in steps:
        want = fine_keys + step
        at = np.searchsorted(fine_keys, want)
        at_c = np.minimum(at, len(fine_keys) - 1)
        hit = fine_keys[at_c] == want
        a_all.append(patch_of_fine[np.flatnonzero(hit)])
        b_all.append(patch_of_fine[at_c[hit]])
    a, b = np.concatenate(a_all), np.concatenate(b_all)
    differ = a != b
    lo, hi = np.minimum(a, b)[differ], np.maximum(a, b)[differ]
    pair = np.unique(lo * (int(patch_of_fine.max()) + 1) + hi)
    n = int(patch_of_fine.max()) + 1
    return pair // n, pair % n


def _moments(
    pts: np.ndarray, patch: np.ndarray, n: int, src: np.ndarray, dst: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroids (P, 3), unit normals (P, 3) and point counts (P,) of the patches. A patch of
    fewer than 6 points takes its normal from itself and its linked neighbours together."""
    count = np.bincount(patch, minlength=n).astype(np.float64)
    s1 = np.stack([np.bincount(patch, pts[:, k], n) for k in range(3)], axis=1)
    s2 = np.empty((n, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            s2[:, i, j] = s2[:, j, i] = np.bincount(patch, pts[:, i] * pts[:, j], n)
    centroid = s1 / count[:, None]
    small = count < 6
    if small.any() and len(src):
        c2, t1, t2 = count.copy(), s1.copy(), s2.copy()
        for a, b in ((src, dst), (dst, src)):
            np.add.at(c2, a, count[b])
            np.add.at(t1, a, s1[b])
            np.add.at(t2, a, s2[b])
        count_n = np.where(small, c2, count)
        s1n = np.where(small[:, None], t1, s1)
        s2n = np.where(small[:, None, None], t2, s2)
    else:
        count_n, s1n, s2n = count, s1, s2
    mean = s1n / count_n[:, None]
    cov = s2n / count_n[:, None, None] - mean[:, :, None] * mean[:, None, :]
    normal = _smallest_vector(cov)
    return centroid, normal, count


def _smallest_vector(cov: np.ndarray) -> np.ndarray:
    """(P, 3) unit eigenvector of the smallest eigenvalue of each (P, 3, 3) symmetric matrix."""
    vec = sym3_eigen(cov)[1]
    norm = np.linalg.norm(vec, axis=1, keepdims=True)
    return vec / np.where(norm > 0, norm, 1.0)


def _keep_links(
    centroid: np.ndarray,
    normal: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    smooth_deg: float,
    convex_tol: float,
) -> np.ndarray:
    """(E,) bool: the links whose patches meet convexly or smoothly (LCCP's criterion)."""
    d = centroid[src] - centroid[dst]
    dist = np.linalg.norm(d, axis=1)
    d = d / np.where(dist > 0, dist, 1.0)[:, None]
    convexity = np.einsum("ij,ij->i", normal[src] - normal[dst], d)
    smooth = np.einsum("ij,ij->i", normal[src], normal[dst]) > np.cos(np.radians(smooth_deg))
    return smooth | (convexity > -convex_tol)


def _absorb_small(
    comp: np.ndarray, small: np.ndarray, src: np.ndarray, dst: np.ndarray
) -> np.ndarray:
    """The small segments (small: (S,) bool) join the other segment they share the most links
    with (crease patches, slivers with mixed normals); those with no such neighbour stay."""
    if not small.any() or len(src) == 0:
        return comp
    a, b = comp[src], comp[dst]
    a, b = np.concatenate([a, b]), np.concatenate([b, a])
    pick = small[a] & ~small[b]
    if not pick.any():
        return comp
    n = len(small)
    pair, votes = np.unique(a[pick] * n + b[pick], return_counts=True)
    order = np.lexsort((-votes, pair // n))
    first = np.ones(len(order), bool)
    first[1:] = (pair // n)[order][1:] != (pair // n)[order][:-1]
    best = pair[order][first]
    target = np.arange(n)
    target[best // n] = best % n
    return target[comp]


def cluster_convex(
    cp: np.ndarray,
    surfaces: list,
    support: np.ndarray,
    params,
    origin: np.ndarray | None,
    stats: dict,
) -> np.ndarray:
    """(M,) int64 convex segment of each candidate point cp (M, 3), metres, z up; -1 for the
    points in the noise band of the surface under them (support: (M,) its id, -1 for none):
    those are the table's and must never link two objects. The band is 3 sigma of the depth
    noise at the point's range (``params.convex_band_sigma * r**2``), at least 3 mm, at most
    2 cm; the range is 1 m when the sensor is not known."""
    height = {s.id: s.height for s in surfaces}
    h = np.array([height.get(int(k), -np.inf) for k in range(int(support.max()) + 1)] or [0.0])
    above = np.full(len(cp), np.inf)
    on = support >= 0
    above[on] = cp[on, 2] - h[support[on]]
    r2 = 1.0 if origin is None else np.sum((cp - np.asarray(origin, float)) ** 2, axis=1)
    band = np.clip(3.0 * params.convex_band_sigma * r2, 0.003, 0.02)
    free = np.flatnonzero(above > band)
    stats["band_points"] = int(len(cp) - len(free))
    lab = np.full(len(cp), -1, np.int64)
    lab[free] = convex_segments(
        cp[free],
        origin,
        fine=params.convex_cell,
        smooth_deg=params.convex_smooth_deg,
        min_points=params.min_points,
        crease_curvature=params.convex_crease_curvature,
    )
    stats["voxels"] = int(lab.max() + 1) if len(lab) else 0
    return lab
