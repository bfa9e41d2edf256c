"""An object's foot: the points in its surface's noise band right under the object.

The bottom few millimetres of an object standing on a table lie within the table's noise
band, so surface detection labels them table. They are the object's where the object itself
comes down to the table over them: a band point whose column (a fine cell in x, y) holds the
object's points no higher than ``reach`` above the surface goes to that object. Table seen
beside or in front of an object lies in other columns; table under an overhang (a lying
can, a chair seat) lies below object points that are higher than ``reach``.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.arrays import _cells_xy

# The largest raster (cells) of an object's feet or of the raised patches around them.
_MAX_RASTER = 4_000_000


def claim_feet(
    xyz: np.ndarray,
    surface: np.ndarray,
    height: np.ndarray,
    obj_xyz: np.ndarray,
    obj_label: np.ndarray,
    obj_surface: np.ndarray,
    obj_height: np.ndarray,
    cell: float,
    reach: float,
) -> np.ndarray:
    """(K,) int64 the object claiming each of K band points, -1 for none.

    xyz: (K, 3) band points, metres, z up; surface: (K,) the surface whose band holds each;
    height: (K,) surface heights by surface id (S,) (indexed by ``surface``). obj_xyz (M, 3),
    obj_label (M,) object of each point (-1: none), obj_surface (M,) the surface under each
    (-1: none), obj_height (S,) as ``height``. A band point goes to the object whose lowest
    point in its ``cell`` column, over the same surface, is at most ``reach`` above it."""
    out = np.full(len(xyz), -1, np.int64)
    low = (obj_label >= 0) & (obj_surface >= 0)
    if not low.any() or len(xyz) == 0:
        return out
    idx = np.flatnonzero(low)
    idx = idx[obj_xyz[idx, 2] - obj_height[obj_surface[idx]] <= reach]
    for sid in np.unique(obj_surface[idx]):
        mine = idx[obj_surface[idx] == sid]
        lo = np.array([obj_xyz[mine, a].min() for a in range(2)])
        i, j = _cells_xy(obj_xyz, mine, lo, cell)
        shape = np.array([i.max() + 1, j.max() + 1])
        if shape[0] * shape[1] > _MAX_RASTER:
            continue  # room structure's feet: left to the surface
        # The lowest object point of each column decides its owner: written last.
        order = np.argsort(-obj_xyz[mine, 2], kind="stable")
        owner = np.full(shape, -1, np.int64)
        owner[i[order], j[order]] = obj_label[mine[order]]
        hi = lo + shape * cell
        q = np.flatnonzero(
            (surface == sid)
            & (xyz[:, 0] >= lo[0])
            & (xyz[:, 1] >= lo[1])
            & (xyz[:, 0] < hi[0])
            & (xyz[:, 1] < hi[1])
        )
        qi, qj = _cells_xy(xyz, q, lo, cell)
        out[q] = owner[np.minimum(qi, shape[0] - 1), np.minimum(qj, shape[1] - 1)]
    return out


def claim_raised(
    xyz: np.ndarray,
    owner: np.ndarray,
    raised: np.ndarray,
    obj_xyz: np.ndarray,
    obj_label: np.ndarray,
    cell: float,
    reach: float,
    min_points: int,
) -> np.ndarray:
    """``owner`` (K,) with the raised patches of the band given out: a patch (``raised``:
    (K,) bool, points a surface found raised above its band, joined by ``cell`` columns)
    goes whole to the object coming down within ``reach`` above it over most of its rim (a
    pot's inner bottom, to the pot); a patch touching no object is an object of its own (a
    sheet, a coaster) when it has ``min_points``, else stays none. New objects take labels
    above ``obj_label``'s."""
    from supportnode.kernels.footprint import label8
    from supportnode.kernels.morphology import binary_dilation

    out = owner.copy()
    q = np.flatnonzero(raised & (out < 0))
    if len(q) == 0:
        return out
    lo = xyz[q, :2].min(axis=0) - 3 * cell
    shape = np.floor((xyz[q, :2].max(axis=0) - lo) / cell).astype(np.int64) + 4
    if shape[0] * shape[1] > _MAX_RASTER:
        return out
    qij = np.stack(_cells_xy(xyz, q, lo, cell), axis=1)
    patch_img = np.zeros(shape, dtype=bool)
    patch_img[qij[:, 0], qij[:, 1]] = True
    patches, n = label8(patch_img)
    # The objects' columns near the patches, their points no higher than reach above them.
    top = xyz[q, 2].max() + reach
    near = np.flatnonzero(obj_label >= 0)
    oij = np.stack(_cells_xy(obj_xyz, near, lo, cell), axis=1)
    ok = np.all((oij >= 0) & (oij < shape), axis=1) & (obj_xyz[near, 2] <= top)
    who = np.full(shape, -1, np.int64)
    who[oij[ok, 0], oij[ok, 1]] = obj_label[near[ok]]
    next_label = int(obj_label.max()) + 1 if len(obj_label) else 0
    of_point = patches[qij[:, 0], qij[:, 1]]
    for p in range(1, n + 1):
        mine = q[of_point == p]
        rim = binary_dilation(binary_dilation(patches == p)) & (who >= 0)  # 2 iterations
        if rim.any():
            out[mine] = np.bincount(who[rim]).argmax()
        elif len(mine) >= min_points:
            out[mine] = next_label
            next_label += 1
    return out
