"""Moments and extremes of runs of points, read in place from a voxel grid's offset columns.

Surface summaries reduce the labelled points of each (voxel, surface) run: numpy gathered the
points' three columns and six products into fresh arrays first, then ran a reduceat on each
(the costliest step of a summary on millions of points). Here each run is one loop. So are
the steps around them over a grid's labels: the labelled points and their voxels
(`labelled`), the runs of one label (`label_runs`), the points newly labelled in some voxels
(`newly_labelled`) and the labels' scatter back to input order (`scatter_lookup`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer


@njit(cache=True, nogil=True)
def _run_moments(
    lx: np.ndarray, ly: np.ndarray, lz: np.ndarray, idx: np.ndarray, run: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    r_count = run.size
    sums = np.empty((r_count, 3))
    outer = np.empty((r_count, 6))
    lo = np.empty((r_count, 3))
    hi = np.empty((r_count, 3))
    for r in range(r_count):
        stop = run[r + 1] if r + 1 < r_count else idx.size
        sx = sy = sz = xx = yy = zz = xy = xz = yz = 0.0
        x0, y0, z0 = np.inf, np.inf, np.inf
        x1, y1, z1 = -np.inf, -np.inf, -np.inf
        for k in range(run[r], stop):
            j = idx[k]
            x, y, z = lx[j], ly[j], lz[j]
            sx += x
            sy += y
            sz += z
            xx += x * x
            yy += y * y
            zz += z * z
            xy += x * y
            xz += x * z
            yz += y * z
            x0, y0, z0 = min(x0, x), min(y0, y), min(z0, z)
            x1, y1, z1 = max(x1, x), max(y1, y), max(z1, z)
        sums[r, 0], sums[r, 1], sums[r, 2] = sx, sy, sz
        outer[r, 0], outer[r, 1], outer[r, 2] = xx, yy, zz
        outer[r, 3], outer[r, 4], outer[r, 5] = xy, xz, yz
        lo[r, 0], lo[r, 1], lo[r, 2] = x0, y0, z0
        hi[r, 0], hi[r, 1], hi[r, 2] = x1, y1, z1
    return sums, outer, lo, hi


@njit(cache=True, nogil=True)
def _range_extremes(
    lx: np.ndarray, ly: np.ndarray, lz: np.ndarray, starts: np.ndarray, counts: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    lo = np.empty((starts.size, 3))
    hi = np.empty((starts.size, 3))
    for r in range(starts.size):
        x0, y0, z0 = np.inf, np.inf, np.inf
        x1, y1, z1 = -np.inf, -np.inf, -np.inf
        for j in range(starts[r], starts[r] + counts[r]):
            x, y, z = lx[j], ly[j], lz[j]
            x0, y0, z0 = min(x0, x), min(y0, y), min(z0, z)
            x1, y1, z1 = max(x1, x), max(y1, y), max(z1, z)
        lo[r, 0], lo[r, 1], lo[r, 2] = x0, y0, z0
        hi[r, 0], hi[r, 1], hi[r, 2] = x1, y1, z1
    return lo, hi


@njit(cache=True, nogil=True)
def _labelled(
    labels: np.ndarray, starts: np.ndarray, counts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    total = 0
    for i in range(labels.size):
        total += labels[i] >= 0
    # One slot past the end: every point is written, only a labelled one kept (no branch
    # per point: a depth image's labels change from point to point, and mispredicted
    # branches cost more than the writes); a branch where labels are few or most points
    # carry one (a map's: predictable, and the writes would be the cost).
    at = np.empty(total + 1, np.int64)
    vox = np.empty(total + 1, np.int64)
    per = np.zeros(starts.size, np.int64)
    last = np.full(starts.size, -1, np.int64)
    mixed = 10 * total > labels.size and 10 * total < 9 * labels.size
    m = 0
    for v in range(starts.size):
        keep = np.int64(-1)
        for i in range(starts[v], starts[v] + counts[v]):
            lab = np.int64(labels[i])
            if mixed:
                at[m], vox[m] = i, v
                on = lab >= 0
                m += on
                keep = lab if on else keep
            elif lab >= 0:
                at[m], vox[m] = i, v
                m += 1
                keep = lab
        last[v] = keep
        per[v] = m
    # Counts from the running total.
    for v in range(starts.size - 1, 0, -1):
        per[v] -= per[v - 1]
    return at[:total], vox[:total], per, last


def _tiling(
    labels: np.ndarray, starts: np.ndarray, counts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """labels (N,), starts and counts (V,) int64, contiguous; ValueError unless the ranges
    ``starts[v] : starts[v] + counts[v]`` tile 0 .. N - 1 in order."""
    lab = np.ascontiguousarray(labels).ravel()
    s = np.ascontiguousarray(starts, dtype=np.int64).ravel()
    c = np.ascontiguousarray(counts, dtype=np.int64).ravel()
    if len(s) != len(c):
        raise ValueError("starts and counts differ in length")
    if int(c.sum()) != len(lab) or (len(s) and (s[0] != 0 or (s[1:] != (s + c)[:-1]).any())):
        raise ValueError("the ranges must tile the labels in order")
    return lab, s, c


def labelled(
    labels: np.ndarray, starts: np.ndarray, counts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The labelled points (``labels`` >= 0) of (N,) labels in the order of V contiguous
    ranges ``starts[v] : starts[v] + counts[v]`` that tile 0 .. N - 1 in order (a voxel
    grid's): their positions (K,) ascending, each one's range (K,), and per range (V,) how
    many and the last one's label (-1: none), all int64. Raises ValueError on shapes or
    ranges that do not tile the labels."""
    return _labelled(*_tiling(labels, starts, counts))


@njit(cache=True, nogil=True)
def _label_runs(
    labels: np.ndarray, starts: np.ndarray, counts: np.ndarray
) -> tuple[np.ndarray, ...]:
    # Branch-free per point (as `_labelled`): labels change from point to point.
    nv = starts.size
    pure = np.zeros(nv, np.bool_)
    first = np.zeros(nv, np.int64)
    big = np.int64(1) << 62
    top = np.int64(-1)
    n_mixed = 0
    n_lab = np.zeros(nv, np.int64)
    for v in range(nv):
        k, lo, hi = 0, big, np.int64(-1)
        for i in range(starts[v], starts[v] + counts[v]):
            lab = np.int64(labels[i])
            on = lab >= 0
            k += on
            lo = min(lo, lab if on else big)
            hi = max(hi, lab)
        pure[v] = k > 0 and k == counts[v] and lo == hi
        first[v], n_lab[v] = lo, k
        top = max(top, hi)
        n_mixed += 0 if pure[v] else k
    present = np.zeros(top + 2, np.int64)  # a last slot for the unlabelled
    idx = np.empty(n_mixed + 1, np.int64)
    run = np.empty(n_mixed + 1, np.int64)
    run_lab = np.empty(n_mixed + 1, np.int64)
    run_vox = np.empty(n_mixed + 1, np.int64)
    m = r = 0
    for v in range(nv):
        if pure[v]:
            present[first[v]] += counts[v]
            continue
        if n_lab[v] == 0:  # nothing labelled (most voxels of a map)
            continue
        prev = np.int64(-1)
        for i in range(starts[v], starts[v] + counts[v]):
            lab = np.int64(labels[i])
            on = lab >= 0
            present[lab if on else top + 1] += 1
            # A new run at the voxel's first labelled point, or at a new label.
            run[r], run_lab[r], run_vox[r] = m, lab, v
            r += on and lab != prev
            prev = lab if on else prev
            idx[m] = i
            m += on
    return pure, present[: top + 1], idx[:m], run[:r], run_lab[:r], run_vox[:r]


def label_runs(
    labels: np.ndarray, starts: np.ndarray, counts: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Runs of one label in V contiguous ranges (a voxel grid's voxels, see `labelled`) of
    (N,) labels (-1: none). Returns whether each range is pure (V,) bool (all its points
    carry one label); then, int64, the points per label (L,) (``np.bincount`` of the labels
    >= 0); and of the other ranges with labelled points, those points' positions (K,) in
    order, runs of one label in one range as starts into them (R,), and each run's label
    (R,) and range (R,)."""
    return _label_runs(*_tiling(labels, starts, counts))


@njit(cache=True, nogil=True)
def _newly_labelled(
    labels: np.ndarray, before: np.ndarray, starts: np.ndarray, counts: np.ndarray, n: int
) -> np.ndarray:
    top = n - 1
    for r in range(starts.size):
        for i in range(starts[r], starts[r] + counts[r]):
            if labels[i] >= 0 and before[i] < 0:
                top = max(top, np.int64(labels[i]))
    out = np.zeros(top + 1, np.int64)
    for r in range(starts.size):
        for i in range(starts[r], starts[r] + counts[r]):
            if labels[i] >= 0 and before[i] < 0:
                out[labels[i]] += 1
    return out


def newly_labelled(
    labels: np.ndarray, before: np.ndarray, starts: np.ndarray, counts: np.ndarray, n: int
) -> np.ndarray:
    """Per label, how many points of the disjoint ranges ``starts[r] : starts[r] + counts[r]``
    carry it in ``labels`` (N,) and carried none (-1) in ``before`` (N,): ``np.bincount`` of
    those labels with ``minlength`` n (int64), read only in the ranges (the points that can
    have changed)."""
    s = np.ascontiguousarray(starts, dtype=np.int64).ravel()
    c = np.ascontiguousarray(counts, dtype=np.int64).ravel()
    if len(labels) != len(before) or len(s) != len(c):
        raise ValueError("labels and before, starts and counts must match in length")
    if len(s) and ((s < 0).any() or (c < 0).any() or (s + c > len(labels)).any()):
        raise ValueError("a range lies outside the labels")
    return _newly_labelled(labels, before, s, c, int(n))


@njit(cache=True, nogil=True)
def _scatter_lookup(out: np.ndarray, rows: np.ndarray, lut: np.ndarray, idx: np.ndarray) -> bool:
    for i in range(rows.size):  # checked first: nothing written when a row is outside
        if rows[i] < 0 or rows[i] >= out.size or idx[i] < -lut.size or idx[i] >= lut.size:
            return False
    for i in range(rows.size):
        out[rows[i]] = lut[idx[i]]  # a negative index from the end, as numpy's
    return True


def scatter_lookup(out: np.ndarray, rows: np.ndarray, lut: np.ndarray, idx: np.ndarray) -> None:
    """``out[rows] = lut[idx]`` in place, in one pass without the (K,) gathered temporary:
    rows (K,) int positions into ``out`` (N,), idx (K,) int positions into ``lut`` (L,) (negative
    ones from the end, as numpy's), ``out`` and ``lut`` of one dtype. Raises ValueError on
    lengths, dtypes or positions outside (then nothing is written)."""
    if len(rows) != len(idx) or out.dtype != lut.dtype or not out.flags.c_contiguous:
        raise ValueError("scatter_lookup: rows and idx of one length, out contiguous like lut")
    if not _scatter_lookup(out, rows, lut, idx):
        raise ValueError("scatter_lookup: a position lies outside out or lut")


def _columns(local: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lx, ly, lz = (np.ascontiguousarray(c, dtype=np.float64) for c in local)
    if not (lx.ndim == ly.ndim == lz.ndim == 1 and len(lx) == len(ly) == len(lz)):
        raise ValueError("local must be three (N,) columns of one length")
    return lx, ly, lz


def run_moments(
    local: list[np.ndarray], idx: np.ndarray, run: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sums, products, least and greatest coordinates of R runs of points.

    local: three (N,) float64 columns x, y, z (metres); idx: (K,) int positions into them;
    run: (R,) int, strictly increasing, ``run[0] == 0`` when R > 0: run r holds
    ``idx[run[r] : run[r + 1]]`` (the last to the end). Returns sums (R, 3), products (R, 6)
    (xx, yy, zz, xy, xz, yz), minima (R, 3), maxima (R, 3), float64. Raises ValueError on
    shapes, positions outside the points or runs that are not increasing.
    """
    lx, ly, lz = _columns(local)
    i = np.ascontiguousarray(idx, dtype=np.int64).ravel()
    r = np.ascontiguousarray(run, dtype=np.int64).ravel()
    if len(i) and (i.min() < 0 or i.max() >= len(lx)):
        raise ValueError(f"positions must lie in [0, {len(lx)})")
    if len(r) and (r[0] != 0 or (np.diff(r) <= 0).any() or r[-1] >= max(len(i), 1)):
        raise ValueError("runs must start at 0 and increase strictly within the positions")
    if len(i) and not len(r):
        raise ValueError("positions given without runs")
    return _run_moments(lx, ly, lz, i, r)


def range_extremes(
    local: list[np.ndarray], starts: np.ndarray, counts: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest x, y, z of R contiguous ranges ``starts[r] : starts[r] + counts[r]``
    of the (N,) columns ``local``: (R, 3) float64 each (inf / -inf for an empty range).
    Raises ValueError on shapes or ranges outside the points."""
    lx, ly, lz = _columns(local)
    s = np.ascontiguousarray(starts, dtype=np.int64).ravel()
    c = np.ascontiguousarray(counts, dtype=np.int64).ravel()
    if len(s) != len(c):
        raise ValueError("starts and counts differ in length")
    if len(s) and ((s < 0).any() or (c < 0).any() or (s + c > len(lx)).any()):
        raise ValueError("a range lies outside the points")
    return _range_extremes(lx, ly, lz, s, c)


@warmer
def _warm() -> None:
    cols = [np.arange(3.0), np.zeros(3), np.ones(3)]
    run_moments(cols, np.array([0, 2]), np.array([0, 1]))
    range_extremes(cols, np.array([0]), np.array([3]))
    labelled(np.array([0, -1, 1], np.int32), np.array([0, 2]), np.array([2, 1]))
    label_runs(np.array([0, -1, 1], np.int32), np.array([0, 2]), np.array([2, 1]))
    lab = np.array([0, -1, 1], np.int32)
    newly_labelled(lab, lab.copy(), np.array([0, 2]), np.array([2, 1]), 2)
    scatter_lookup(np.zeros(3, np.int32), np.arange(3), np.array([5, -1], np.int32), lab)
