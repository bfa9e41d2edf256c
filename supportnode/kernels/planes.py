"""Points labelled by the plane of a surface voxel: one loop over each voxel's points.

The planar surface method labels a point when it lies within tolerance of the plane of a
surface voxel in its column; numpy spent a dozen (N,) temporaries (repeats, gathers, masks)
on what is one comparison per point here.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True)
def _label(
    lx: np.ndarray,
    ly: np.ndarray,
    lz: np.ndarray,
    first: np.ndarray,
    count: np.ndarray,
    a: np.ndarray,
    bx: np.ndarray,
    by: np.ndarray,
    label: np.ndarray,
    tol: np.ndarray,
    labels: np.ndarray,
    best: np.ndarray,
    nearer: bool,
) -> int:
    # The input checked first, nothing written when it fails (1: a run outside the points,
    # 2: a plane not finite): one loop over the runs, not six numpy passes and temporaries.
    for p in range(first.size):
        if first[p] < 0 or count[p] < 0 or first[p] + count[p] > lx.size:
            return 1
    for p in range(first.size):
        if not (np.isfinite(a[p]) and np.isfinite(bx[p]) and np.isfinite(by[p])):
            return 2
    for p in range(first.size):
        ap, bxp, byp, lab, t = a[p], bx[p], by[p], label[p], tol[p]
        for j in range(first[p], first[p] + count[p]):
            # The same operations in the same order as numpy's: the same bits.
            r = lz[j] - (ap + bxp * lx[j] + byp * ly[j])
            d = abs(r)
            if d <= t and not (nearer and labels[j] >= 0 and not d < abs(best[j])):
                labels[j] = lab
                best[j] = r
    return 0


def label_by_planes(
    local: list[np.ndarray],
    first: np.ndarray,
    count: np.ndarray,
    plane: tuple[np.ndarray, np.ndarray, np.ndarray],
    label: np.ndarray,
    tol: np.ndarray,
    labels: np.ndarray,
    best: np.ndarray,
    nearer: bool,
) -> None:
    """Label, in place, the points of P runs that lie within ``tol`` of a plane each.

    local: three (N,) float64 columns x, y, z, metres (a voxel grid's corner offsets); run p
    covers points ``first[p] : first[p] + count[p]`` (runs applied in order: a later
    run overlapping an earlier one sees its labels), its plane is
    z = a + bx x + by y with ``plane = (a, bx, by)``, each (P,) float64. label: (P,) int,
    tol: (P,) float64 m. A point within tolerance takes the run's label into ``labels`` ((N,)
    int32) and its height above the plane into ``best`` ((N,) float64, signed); with
    ``nearer`` a labelled point (labels >= 0) only for a smaller distance than ``|best|``. Raises ValueError on shapes,
    dtypes, runs outside the points or non-finite planes.
    """
    lx, ly, lz = (np.ascontiguousarray(c, dtype=np.float64) for c in local)
    n = len(lx)
    if not (len(ly) == len(lz) == n == len(labels) == len(best)):
        raise ValueError("local columns, labels and best must have one length")
    if labels.dtype != np.int32 or best.dtype != np.float64:
        raise ValueError("labels must be int32 and best float64 (written in place)")
    if not (labels.flags.c_contiguous and best.flags.c_contiguous):
        raise ValueError("labels and best must be contiguous (written in place)")
    f = np.ascontiguousarray(first, dtype=np.int64)
    c = np.ascontiguousarray(count, dtype=np.int64)
    a, bx, by = (np.ascontiguousarray(x, dtype=np.float64) for x in plane)
    lab = np.ascontiguousarray(label, dtype=np.int32)
    t = np.ascontiguousarray(tol, dtype=np.float64)
    if not (len(c) == len(f) == len(a) == len(bx) == len(by) == len(lab) == len(t)):
        raise ValueError("run and plane arrays must have one length")
    bad = _label(lx, ly, lz, f, c, a, bx, by, lab, t, labels, best, bool(nearer))
    if bad:
        raise ValueError("a run lies outside the points" if bad == 1 else "planes must be finite")


@njit(cache=True, nogil=True)
def _inliers(lx, ly, lz, first, count, rel, bx, by, tol):
    n_in = np.zeros(first.size, np.int64)
    for p in range(first.size):
        r0, r1, r2, b0, b1, t = rel[p, 0], rel[p, 1], rel[p, 2], bx[p], by[p], tol[p]
        m = 0
        for j in range(first[p], first[p] + count[p]):
            # As numpy's |o0 * bx + o1 * by + o2| of the offsets o from the plane's point.
            m += abs((lx[j] - r0) * b0 + (ly[j] - r1) * b1 + (lz[j] - r2)) <= t
        n_in[p] = m
    return n_in


def plane_inliers(
    local: list[np.ndarray],
    first: np.ndarray,
    count: np.ndarray,
    rel: np.ndarray,
    slope: tuple[np.ndarray, np.ndarray],
    tol: np.ndarray,
) -> np.ndarray:
    """(P,) int64: per run p (points ``first[p] : first[p] + count[p]`` of the three (N,)
    float64 columns ``local``, metres), how many lie within ``tol[p]`` m (vertically) of the
    plane through ``rel[p]`` (P, 3) with ``slope`` (bx, by), each (P,): |(x - rx) bx +
    (y - ry) by + (z - rz)| <= tol. One pass over the runs' points, no (N,) temporaries.
    Raises ValueError on shapes or runs outside the points."""
    return _inliers(*_runs(local, first, count, rel, slope, tol))


def _runs(
    local: list[np.ndarray],
    first: np.ndarray,
    count: np.ndarray,
    rel: np.ndarray,
    slope: tuple[np.ndarray, np.ndarray],
    tol: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """The arguments of `plane_inliers` as its kernels take them: contiguous, checked."""
    lx, ly, lz = (np.ascontiguousarray(c, dtype=np.float64) for c in local)
    if not len(lx) == len(ly) == len(lz):
        raise ValueError("local columns must have one length")
    f = np.ascontiguousarray(first, dtype=np.int64)
    c = np.ascontiguousarray(count, dtype=np.int64)
    r = np.ascontiguousarray(rel, dtype=np.float64).reshape(-1, 3)
    bx, by = (np.ascontiguousarray(x, dtype=np.float64) for x in slope)
    t = np.ascontiguousarray(tol, dtype=np.float64)
    if not (len(c) == len(f) == len(r) == len(bx) == len(by) == len(t)):
        raise ValueError("run and plane arrays must have one length")
    if len(f) and ((f < 0).any() or (c < 0).any() or (f + c > len(lx)).any()):
        raise ValueError("a run lies outside the points")
    return lx, ly, lz, f, c, r, bx, by, t


@njit(cache=True, nogil=True)
def _inlier_moments(lx, ly, lz, first, count, rel, bx, by, tol):
    n = first.size
    lo = np.empty((n, 2))
    hi = np.empty((n, 2))
    sums = np.empty((n, 3))
    outer = np.empty((n, 6))
    for p in range(n):
        r0, r1, r2, b0, b1, t = rel[p, 0], rel[p, 1], rel[p, 2], bx[p], by[p], tol[p]
        x0, y0, x1, y1 = np.inf, np.inf, -np.inf, -np.inf
        sx = sy = sz = xx = yy = zz = xy = xz = yz = 0.0
        for j in range(first[p], first[p] + count[p]):
            ox, oy, oz = lx[j] - r0, ly[j] - r1, lz[j] - r2
            if abs(ox * b0 + oy * b1 + oz) <= t:  # as _inliers counts them
                x0, y0, x1, y1 = min(x0, ox), min(y0, oy), max(x1, ox), max(y1, oy)
                sx += ox
                sy += oy
                sz += oz
                xx += ox * ox
                yy += oy * oy
                zz += oz * oz
                xy += ox * oy
                xz += ox * oz
                yz += oy * oz
        lo[p, 0], lo[p, 1], hi[p, 0], hi[p, 1] = x0, y0, x1, y1
        sums[p, 0], sums[p, 1], sums[p, 2] = sx, sy, sz
        outer[p, 0], outer[p, 1], outer[p, 2] = xx, yy, zz
        outer[p, 3], outer[p, 4], outer[p, 5] = xy, xz, yz
    return lo, hi, sums, outer


def inlier_moments(
    local: list[np.ndarray],
    first: np.ndarray,
    count: np.ndarray,
    rel: np.ndarray,
    slope: tuple[np.ndarray, np.ndarray],
    tol: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per run p, of its points that `plane_inliers` counts (same arguments), offsets o from
    ``rel[p]``, metres: the x, y box lo, hi (P, 2) (inf, -inf for none), the sums (P, 3) of
    o and of its products (P, 6) xx, yy, zz, xy, xz, yz (``voxels.OUTER_INDEX``), added in
    the points' order. Raises ValueError as plane_inliers does."""
    return _inlier_moments(*_runs(local, first, count, rel, slope, tol))


@warmer
def _warm() -> None:
    cols = [np.zeros(2), np.zeros(2), np.array([0.0, 0.5])]
    one = np.zeros(1)
    labels, best = np.full(2, -1, np.int32), np.empty(2)
    run = np.zeros(1, np.int64), np.full(1, 2, np.int64)
    label_by_planes(cols, *run, (one, one, one), np.zeros(1), np.full(1, 0.1), labels, best, True)
    plane_inliers(cols, *run, np.zeros((1, 3)), (one, one), np.full(1, 0.1))
    inlier_moments(cols, *run, np.zeros((1, 3)), (one, one), np.full(1, 0.1))
