"""One pass over a scan's points for what lies in a surface's noise band.

The band steps (raised patches of a table's band, the objects' feet) each picked the band's
points out of a whole depth image with numpy: a mask, a gather, a sort key per point, then a
reduction, several passes over ~300k points for a few thousand that matter. Here each is one
loop over the points, in grid order where a grid is given.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True, inline="always")
def _column_of(
    lx: np.ndarray, ly: np.ndarray, i: int, per0: int, per1: int, edge: np.ndarray
) -> tuple[int, int]:
    """Point i's column in its voxel: x and y over the voxel's edge (the same division as
    numpy's of the whole column, point by point: no (N,) temporaries), times the columns."""
    li = min(int((lx[i] / edge[0]) * per0), per0 - 1)
    lj = min(int((ly[i] / edge[1]) * per1), per1 - 1)
    return li, lj


@njit(cache=True, nogil=True)
def _column_sums(
    starts: np.ndarray,
    counts: np.ndarray,
    lx: np.ndarray,
    ly: np.ndarray,
    labels: np.ndarray,
    use: np.ndarray,
    col: np.ndarray,
    edge: np.ndarray,
    value: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    per0, per1 = col[0], col[1]
    n_keys = starts.size * per0 * per1
    n = np.zeros(n_keys, np.int64)
    total = np.zeros(n_keys)
    comp = np.full(starts.size, -1, np.int64)
    for v in range(starts.size):
        for i in range(starts[v], starts[v] + counts[v]):
            lab = labels[i]
            if lab < 0 or not use[lab]:
                continue
            li, lj = _column_of(lx, ly, i, per0, per1, edge)
            key = (v * per0 + li) * per1 + lj
            n[key] += 1
            total[key] += value[i]
            comp[v] = lab
    return n, total, comp


_GridArgs = tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
]


def _grid_args(
    starts: np.ndarray,
    counts: np.ndarray,
    local: list[np.ndarray],
    size: np.ndarray,
    labels: np.ndarray,
    use: np.ndarray,
    per: np.ndarray,
) -> _GridArgs:
    """The column kernels' common arguments, checked and made contiguous (the labels in
    their own integer type: no (N,) copy)."""
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    counts = np.ascontiguousarray(counts, dtype=np.int64)
    lab = np.ascontiguousarray(labels)
    if lab.dtype.kind not in "iu":
        lab = lab.astype(np.int64)
    if len(starts) != len(counts):
        raise ValueError("starts and counts must match in length")
    if len(starts) and (starts + counts).max() > len(lab):
        raise ValueError("a voxel's points lie outside the points")
    if len(lab) and lab.max() >= len(use):
        raise ValueError("a label has no entry in use")
    lx = np.ascontiguousarray(local[0], dtype=np.float64)
    ly = np.ascontiguousarray(local[1], dtype=np.float64)
    col = np.ascontiguousarray(per, dtype=np.int64)
    edge = np.array([float(size[0]), float(size[1])])  # the kernels divide x, y by it
    return starts, counts, lx, ly, lab, np.asarray(use, np.bool_), col, edge


def column_sums(
    starts: np.ndarray,
    counts: np.ndarray,
    local: list[np.ndarray],
    size: np.ndarray,
    labels: np.ndarray,
    use: np.ndarray,
    value: np.ndarray,
    per: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column of each voxel (``per`` (2,) columns along x and y of a voxel ``size`` (3,)
    metres): the count (V * per0 * per1,) and the sum of ``value`` (N,) over the points in
    grid order whose label (N,) is a surface marked in ``use`` (S,) bool; and each voxel's
    surface (V,) (the last such label; -1 for none). Voxel v's points are
    ``starts[v] : starts[v] + counts[v]``; ``local``: their x, y, z in the voxel, metres.
    Column keys are ``(v * per0 + i) * per1 + j``."""
    val = np.ascontiguousarray(value, dtype=np.float64)
    if len(labels) != len(val):
        raise ValueError("labels and values must match in length")
    return _column_sums(*_grid_args(starts, counts, local, size, labels, use, per), val)


@njit(cache=True, nogil=True)
def _any_in(flags: np.ndarray, start: int, stop: int) -> bool:
    # A loop, not ndarray.any(): numba's lives in numba.np.arraymath, which a cache load then
    # imports, and with it scipy's BLAS (~80 ms of a fresh `supportnode detect`).
    for i in range(start, stop):
        if flags[i]:
            return True
    return False


@njit(cache=True, nogil=True)
def _in_columns(
    starts: np.ndarray,
    counts: np.ndarray,
    lx: np.ndarray,
    ly: np.ndarray,
    labels: np.ndarray,
    use: np.ndarray,
    col: np.ndarray,
    edge: np.ndarray,
    flagged: np.ndarray,
) -> np.ndarray:
    per0, per1 = col[0], col[1]
    out = np.empty(lx.size, np.int64)
    m = 0
    for v in range(starts.size):
        # Only the voxels with a flagged column (a few: raised patches are small).
        base = v * per0 * per1
        if not _any_in(flagged, base, base + per0 * per1):
            continue
        for i in range(starts[v], starts[v] + counts[v]):
            lab = labels[i]
            if lab < 0 or not use[lab]:
                continue
            li, lj = _column_of(lx, ly, i, per0, per1, edge)
            if flagged[(v * per0 + li) * per1 + lj]:
                out[m] = i
                m += 1
    return out[:m].copy()


def points_in_columns(
    starts: np.ndarray,
    counts: np.ndarray,
    local: list[np.ndarray],
    size: np.ndarray,
    labels: np.ndarray,
    use: np.ndarray,
    flagged: np.ndarray,
    per: np.ndarray,
) -> np.ndarray:
    """The positions (grid order, ascending) of the points counted by :func:`column_sums`
    (same arguments) that lie in a column ``flagged`` (V * per0 * per1,) bool."""
    if len(flagged) != len(starts) * int(per[0]) * int(per[1]):
        raise ValueError("flagged must have one entry per column")
    args = _grid_args(starts, counts, local, size, labels, use, per)
    return _in_columns(*args, np.asarray(flagged, np.bool_))


@njit(cache=True, nogil=True)
def _band_rows(
    pts: np.ndarray,
    labels: np.ndarray,
    use: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    always: np.ndarray,
) -> np.ndarray:
    out = np.empty(labels.size, np.int64)
    m = 0
    for i in range(labels.size):
        lab = labels[i]
        if lab < 0 or not use[lab]:
            continue
        x, y = pts[i, 0], pts[i, 1]
        if always[i] or (x >= lo[0] and x <= hi[0] and y >= lo[1] and y <= hi[1]):
            out[m] = i
            m += 1
    return out[:m].copy()


def band_rows(
    points: np.ndarray,
    labels: np.ndarray,
    use: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    always: np.ndarray,
) -> np.ndarray:
    """Rows (ascending) of the ``points`` (N, 3), metres, whose label (N,) is a surface marked
    in ``use`` (S,) bool and whose x, y lie in the box [lo, hi] (2,), or that are marked in
    ``always`` (N,) bool."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    lab = np.ascontiguousarray(labels)  # in its own integer type: no (N,) copy
    if lab.dtype.kind not in "iu":
        lab = lab.astype(np.int64)
    if len(lab) != len(pts) or len(always) != len(pts):
        raise ValueError("points, labels and always must match in length")
    if len(lab) and lab.max() >= len(use):
        raise ValueError("a label has no entry in use")
    box = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    return _band_rows(pts, lab, np.asarray(use, np.bool_), *box, np.asarray(always, np.bool_))


@njit(cache=True, nogil=True)
def _label_voxel_counts(
    labels: np.ndarray, at: np.ndarray, vox: np.ndarray, n_comp: int, n_vox: int, dense: bool
) -> tuple[np.ndarray, np.ndarray, bool]:
    count = np.zeros(n_comp, np.int64)
    w = np.zeros(n_comp * n_vox if dense else 0, np.int64)
    for k in range(at.size):
        c = labels[at[k]]
        if c >= n_comp:
            return count, w, False
        count[c] += 1
        if dense:
            w[c * n_vox + vox[k]] += 1
    return count, w, True


def label_voxel_counts(
    labels: np.ndarray, at: np.ndarray, vox: np.ndarray, n_comp: int, n_vox: int, dense: bool
) -> tuple[np.ndarray, np.ndarray] | None:
    """Points per label (n_comp,) int64 of the labelled points at positions ``at`` (K,) of
    ``labels`` (N,) (each >= 0), and with ``dense`` per (label, voxel) as one (n_comp * n_vox,)
    int64 table (``label * n_vox + vox``; ``vox`` (K,) each point's voxel), else an empty one:
    what ``np.bincount`` of the labels and of those keys gives. None when a label is not
    below n_comp."""
    count, w, ok = _label_voxel_counts(labels, at, vox, int(n_comp), int(n_vox), bool(dense))
    return (count, w) if ok else None


@warmer
def _warm() -> None:
    starts, counts = np.array([0]), np.array([2])
    local = [np.array([0.1, 0.9]), np.array([0.1, 0.9]), np.zeros(2)]
    size, per, use = np.ones(3), np.array([2, 2]), np.array([True])
    for lab in (np.array([0, 0]), np.array([0, 0], np.int32)):  # a grid's labels are int32
        column_sums(starts, counts, local, size, lab, use, np.ones(2), per)
        points_in_columns(starts, counts, local, size, lab, use, np.ones(4, bool), per)
        band_rows(np.zeros((2, 3)), lab, use, np.zeros(2), np.ones(2), np.zeros(2, bool))
    lab = np.array([0, -1, 1], np.int32)
    label_voxel_counts(lab, np.array([0, 2]), np.array([0, 1]), 2, 2, True)
