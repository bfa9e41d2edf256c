"""Voxelizing a cloud for detection: each point's voxel, the voxels' counts and moments.

`geometry.voxels.voxelize` on a box of few possible keys (the usual case), in two compiled
passes instead of a dozen numpy ones: the keys' range, then the keys, a counting sort of the
points by voxel (stable: a voxel's points keep their input order), their offsets from the
voxel's corner and the moments. The same bits as the numpy path: the same floating-point
operations per point, and each voxel's sums added as ``numpy.add.reduceat`` adds them (the
voxel's first value plus numpy's pairwise sum of the rest). Releases the interpreter lock.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["key_range", "voxel_grid"]

# numpy's pairwise summation: blocks of this many values are summed with eight accumulators.
_BLOCK = 128
# OUTER_INDEX of supportnode.geometry.voxels: xx, yy, zz, xy, xz, yz.
_PAIRS = np.array([[0, 0], [1, 1], [2, 2], [0, 1], [0, 2], [1, 2]], np.int64)


@njit(cache=True, nogil=True)
def _key_range(pts, size):
    # The least and greatest coordinates, then their keys: x / s and its floor are monotonic
    # in x (IEEE division rounds monotonically), so the extreme keys are the extreme points'
    # keys: two divisions per axis, not one per point. Six scalar chains, not one through
    # an array per axis: the loop is bound by their latency.
    x0 = y0 = z0 = np.inf
    x1 = y1 = z1 = -np.inf
    bad = 0.0
    for i in range(pts.shape[0]):
        x, y, z = pts[i, 0], pts[i, 1], pts[i, 2]
        bad += (x - x) + (y - y) + (z - z)  # NaN from then on once a value is NaN or inf
        x0, x1 = min(x0, x), max(x1, x)
        y0, y1 = min(y0, y), max(y1, y)
        z0, z1 = min(z0, z), max(z1, z)
    lo = np.array([x0, y0, z0])
    hi = np.array([x1, y1, z1])
    finite = bad == 0.0
    if pts.shape[0] == 0:
        return lo, hi, finite
    for a in range(3):
        # Both ends' keys, ordered: a negative size would turn them round.
        k0, k1 = np.floor(lo[a] / size[a]), np.floor(hi[a] / size[a])
        lo[a], hi[a] = min(k0, k1), max(k0, k1)
        # A quotient that overflows (or a NaN size) shows at the ends.
        finite = finite and math.isfinite(k0) and math.isfinite(k1)
    return lo, hi, finite


@njit(cache=True, nogil=True)
def _value(a, b, i, product):
    return a[i] * b[i] if product else a[i]


@njit(cache=True, nogil=True)
def _pairwise(a, b, start, n, product):
    """numpy's pairwise sum of a[start:start + n] (product: of a * b), to the bit."""
    if n < 8:
        res = 0.0
        for i in range(start, start + n):
            res += _value(a, b, i, product)
        return res
    if n <= _BLOCK:
        # Eight accumulators as scalars (an array would be allocated per call).
        r0 = _value(a, b, start, product)
        r1 = _value(a, b, start + 1, product)
        r2 = _value(a, b, start + 2, product)
        r3 = _value(a, b, start + 3, product)
        r4 = _value(a, b, start + 4, product)
        r5 = _value(a, b, start + 5, product)
        r6 = _value(a, b, start + 6, product)
        r7 = _value(a, b, start + 7, product)
        i = start + 8
        end = start + n - (n % 8)
        while i < end:
            r0 += _value(a, b, i, product)
            r1 += _value(a, b, i + 1, product)
            r2 += _value(a, b, i + 2, product)
            r3 += _value(a, b, i + 3, product)
            r4 += _value(a, b, i + 4, product)
            r5 += _value(a, b, i + 5, product)
            r6 += _value(a, b, i + 6, product)
            r7 += _value(a, b, i + 7, product)
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < start + n:
            res += _value(a, b, i, product)
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise(a, b, start, n2, product) + _pairwise(a, b, start + n2, n - n2, product)


@njit(cache=True, nogil=True)
def _linear_keys(pts, size, origin, dims, top):
    """Each point's linear key (N,) and the points per key (top + 1,)."""
    n = pts.shape[0]
    lin = np.empty(n, np.int64)
    count = np.zeros(top + 1, np.int64)
    for i in range(n):
        k = np.int64(0)
        for a in range(3):  # ((k0 - o0) * d1 + k1 - o1) * d2 + k2 - o2, as the numpy path
            k = k * dims[a] + (np.int64(np.floor(pts[i, a] / size[a])) - origin[a])
        lin[i] = k
        count[k] += 1
    return lin, count


@njit(cache=True, nogil=True)
def _ranks(rank, size, origin, dims):
    """The occupied keys of the counts per key ``rank`` (top + 1,), which become each key's
    voxel: their keys (V, 3), corners (V, 3) m, counts and starts (V,)."""
    nv = 0
    for k in range(rank.size):
        nv += rank[k] > 0
    keys = np.empty((nv, 3), np.int64)
    corner = np.empty((nv, 3))
    counts = np.empty(nv, np.int64)
    starts = np.empty(nv, np.int64)
    v = 0
    at = 0
    k = 0
    # Counts become ranks: ascending keys, each voxel's key from the loop's indices (no
    # division of the linear keys afterwards).
    for i0 in range(dims[0]):
        for i1 in range(dims[1]):
            for i2 in range(dims[2]):
                c = rank[k]
                if c > 0:
                    keys[v, 0] = i0 + origin[0]
                    keys[v, 1] = i1 + origin[1]
                    keys[v, 2] = i2 + origin[2]
                    for a in range(3):  # floor(p / size) * size of its points, exactly
                        corner[v, a] = np.float64(keys[v, a]) * size[a]
                    counts[v], starts[v] = c, at
                    at += c
                    rank[k] = v
                    v += 1
                k += 1
    return keys, corner, counts, starts


@njit(cache=True, nogil=True)
def _sort_points(pts, size, origin, dims, top):
    """Each point's voxel rank, the voxels' keys (V, 3) and counts, the points' order (a
    stable counting sort by voxel) and their offsets from the corner, in that order."""
    n = pts.shape[0]
    lin, rank = _linear_keys(pts, size, origin, dims, top)
    keys, corner, counts, starts = _ranks(rank, size, origin, dims)
    fill = np.empty(counts.size, np.int64)
    for v in range(counts.size):  # loops, not slice copies: those compile for seconds
        fill[v] = starts[v]
    order = np.empty(n, np.int64)
    point_voxel = np.empty(n, np.int64)
    srt = np.empty((3, n))
    for i in range(n):
        # Each point's offsets written straight to its sorted place: reading the points in
        # order and writing to one stream per voxel beats gathering them afterwards.
        v = rank[lin[i]]
        point_voxel[i] = v
        j = fill[v]
        fill[v] = j + 1
        order[j] = i
        for a in range(3):
            # p - floor(p / size) * size with the voxel's corner; + 0.0 as there: a floor
            # of -0.0 (p = -0.0) gave +0.0, where p - 0.0 leaves -0.0.
            srt[a, j] = (pts[i, a] - corner[v, a]) + 0.0
    return keys, counts, starts, order, point_voxel, srt


@njit(cache=True, nogil=True)
def _values(srt, i, out):
    """The nine moment terms of point i: x, y, z, then xx, yy, zz, xy, xz, yz."""
    x, y, z = srt[0, i], srt[1, i], srt[2, i]
    out[0], out[1], out[2] = x, y, z
    out[3], out[4], out[5] = x * x, y * y, z * z
    out[6], out[7], out[8] = x * y, x * z, y * z


@njit(cache=True, nogil=True)
def _block_sums(srt, start, n, res, acc, val):
    """numpy's pairwise sums of the nine terms over points start .. start + n - 1, all nine
    in one pass over the points, for n <= _BLOCK (one block: eight accumulators)."""
    if n < 8:
        for m in range(9):
            res[m] = 0.0
        for i in range(start, start + n):
            _values(srt, i, val)
            for m in range(9):
                res[m] += val[m]
        return
    for k in range(8):
        _values(srt, start + k, val)
        for m in range(9):
            acc[m, k] = val[m]
    i = start + 8
    end = start + n - (n % 8)
    while i < end:
        for k in range(8):
            _values(srt, i + k, val)
            for m in range(9):
                acc[m, k] += val[m]
        i += 8
    for m in range(9):
        res[m] = ((acc[m, 0] + acc[m, 1]) + (acc[m, 2] + acc[m, 3])) + (
            (acc[m, 4] + acc[m, 5]) + (acc[m, 6] + acc[m, 7])
        )
    while i < start + n:
        _values(srt, i, val)
        for m in range(9):
            res[m] += val[m]
        i += 1


@njit(cache=True, nogil=True)
def _moments(srt, starts, counts, pairs):
    """Per voxel, the sums (V, 3) and outer products (V, 6) as numpy.add.reduceat adds them:
    the first value, plus the pairwise sum of the others."""
    nv = starts.size
    sums = np.empty((nv, 3))
    outer = np.empty((nv, 6))
    first = np.empty(9)
    res = np.empty(9)
    acc = np.empty((9, 8))
    val = np.empty(9)
    for v in range(nv):
        s, n = starts[v], counts[v] - 1
        _values(srt, s, first)
        if n <= _BLOCK:
            _block_sums(srt, s + 1, n, res, acc, val)
        else:  # long runs: numpy splits them in halves, term by term
            for a in range(3):
                res[a] = _pairwise(srt[a], srt[a], s + 1, n, False)
            for col in range(6):
                res[3 + col] = _pairwise(srt[pairs[col, 0]], srt[pairs[col, 1]], s + 1, n, True)
        for a in range(3):
            sums[v, a] = first[a] + res[a]
        for col in range(6):
            outer[v, col] = first[3 + col] + res[3 + col]
    return sums, outer


def key_range(pts: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """The smallest and largest floored keys floor(p / size) of (N, 3) float64 points
    (metres; N >= 1) per axis, two (3,) float64, and whether they are all finite."""
    lo, hi, finite = _key_range(pts, np.ascontiguousarray(size, np.float64))
    return lo, hi, bool(finite)


def voxel_grid(
    pts: np.ndarray, size: np.ndarray, origin: np.ndarray, dims: np.ndarray
) -> tuple[np.ndarray, ...]:
    """The voxels of (N, 3) float64 points (finite, metres) of edge ``size`` (3,), whose
    keys less ``origin`` (3,) int64 lie in a box of ``dims`` (3,) int64 keys (at most a few
    million: one counter each): keys (V, 3) int64 ascending (x slowest), counts (V,), starts (V,),
    the points' order (N,) (by voxel, stable), each point's voxel (N,), the sorted offsets from
    the corner (3, N) float64, sums (V, 3) and outer products (V, 6) (``OUTER_INDEX``), all as
    `geometry.voxels.voxelize` computes them."""
    size = np.ascontiguousarray(size, np.float64)
    origin = np.ascontiguousarray(origin, np.int64)
    dims = np.ascontiguousarray(dims, np.int64)
    top = int(np.prod(dims)) - 1
    keys, counts, starts, order, voxel, srt = _sort_points(pts, size, origin, dims, top)
    sums, outer = _moments(srt, starts, counts, _PAIRS)
    return keys, counts, starts, order, voxel, srt, sums, outer


@warmer
def _warm() -> None:
    pts = np.zeros((12, 3))
    pts[:, 0] = [0.01, 0.02, 0.31] + [0.05] * 9
    pts[:, 2] = np.linspace(0.0, 0.04, 12)
    size = np.array([0.1, 0.1, 0.05])
    lo, hi, _ = key_range(pts, size)
    origin, dims = lo.astype(np.int64), (hi - lo).astype(np.int64) + 1
    voxel_grid(pts, size, origin, dims)
