"""Per-label work in one pass over the labels, without grouping rows by a sort first: a few
rows of each label picked by rank, each label's bounding box; and rows grouped by label by a
counting sort (two passes) where a stable sort of the labels was used.

The node's obstacles message carries a few evenly spaced points of each cluster: grouping
all of a map's labelled points by a stable sort to keep 64 of each cost a sort of ~100k
labels a scan. Here one pass counts, one pass picks.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["group_rows", "label_boxes", "rows_at_ranks", "rows_by_key", "run_sums"]


@njit(cache=True, nogil=True)
def _rows_at_ranks(labels: np.ndarray, ranks: np.ndarray, starts: np.ndarray) -> np.ndarray:
    n = len(starts) - 1
    out = np.full(len(ranks), -1, np.int64)
    seen = np.zeros(n, np.int64)  # rows of each label met so far
    nxt = starts[:-1].copy()  # each label's next wanted rank, as an index into ranks
    for i in range(len(labels)):
        lab = labels[i]
        if lab < 0 or lab >= n:
            continue
        r = seen[lab]
        seen[lab] = r + 1
        while nxt[lab] < starts[lab + 1] and ranks[nxt[lab]] == r:
            out[nxt[lab]] = i
            nxt[lab] += 1
    return out


def rows_at_ranks(labels: np.ndarray, ranks: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Row of the point of each wanted rank: ``ranks[starts[c]:starts[c + 1]]`` (ascending)
    are ranks among label c's rows of ``labels`` (M,) int (-1: none) in row order, for labels
    0..C-1 (starts (C + 1,) int64). Returns (len(ranks),) int64 rows, -1 where label c has no
    row of that rank. The same as ``np.flatnonzero(labels == c)[ranks]`` for each c."""
    lab = np.ascontiguousarray(labels, dtype=np.int64)  # one signature, the one warmed
    rk = np.ascontiguousarray(ranks, dtype=np.int64)
    st = np.ascontiguousarray(starts, dtype=np.int64)
    if st.ndim != 1 or len(st) < 1 or st[0] != 0 or st[-1] != len(rk) or (np.diff(st) < 0).any():
        raise ValueError("rows_at_ranks: starts must ascend from 0 to len(ranks)")
    return _rows_at_ranks(lab, rk, st)


@njit(cache=True, nogil=True, inline="always")
def _widen(lo: np.ndarray, hi: np.ndarray, points: np.ndarray, i: int, lab: int) -> None:
    # Label lab's box (rows of lo, hi) widened to take row i of points.
    for a in range(points.shape[1]):
        v = points[i, a]
        if v < lo[lab, a]:
            lo[lab, a] = v
        if v > hi[lab, a]:
            hi[lab, a] = v


@njit(cache=True, nogil=True)
def _label_boxes(points: np.ndarray, labels: np.ndarray, n: int) -> tuple:
    d = points.shape[1]
    lo = np.full((n, d), np.inf)
    hi = np.full((n, d), -np.inf)
    for i in range(len(labels)):
        lab = labels[i]
        if lab < 0 or lab >= n:
            continue
        _widen(lo, hi, points, i, lab)
    return lo, hi


def label_boxes(points: np.ndarray, labels: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (n, D) float64: the box of the rows of ``points`` (M, D) of each label
    0..n-1 of ``labels`` (M,) int (others ignored); inf, -inf for a label with no row. The
    same values as per-label ``min``/``max``, without grouping the rows first."""
    # Contiguous, int64: one compiled signature, the one warmed.
    pts = np.ascontiguousarray(points, dtype=np.float64)
    lab = np.ascontiguousarray(labels, dtype=np.int64)
    if pts.ndim != 2 or lab.shape != (len(pts),):
        raise ValueError(
            f"label_boxes: points (M, D) and labels (M,), got {pts.shape}, {lab.shape}"
        )
    return _label_boxes(pts, lab, int(n))


@njit(cache=True, nogil=True)
def _group_rows(points: np.ndarray, labels: np.ndarray, n: int) -> tuple:
    d = points.shape[1]
    count = np.zeros(n, np.int64)
    lo = np.full((n, d), np.inf)
    hi = np.full((n, d), -np.inf)
    for i in range(len(labels)):  # counts and boxes
        lab = labels[i]
        if lab < 0 or lab >= n:
            continue
        count[lab] += 1
        _widen(lo, hi, points, i, lab)
    start = np.empty(n + 1, np.int64)
    start[0] = 0
    for c in range(n):
        start[c + 1] = start[c] + count[c]
    fill = np.empty(n, np.int64)
    for c in range(n):  # a loop, not a slice copy: those compile for seconds
        fill[c] = start[c]
    rows = np.empty(start[n], np.int64)
    grouped = np.empty((start[n], d))
    for i in range(len(labels)):  # each row straight to its place, in row order per label
        lab = labels[i]
        if lab < 0 or lab >= n:
            continue
        j = fill[lab]
        fill[lab] = j + 1
        rows[j] = i
        for a in range(d):
            grouped[j, a] = points[i, a]
    return start, rows, grouped, lo, hi


def group_rows(
    points: np.ndarray, labels: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows of ``points`` (M, D) float64 grouped by their ``labels`` (M,) int, labels
    0..n-1 (others left out): (start (n + 1,) int64, each label's run in the next two; rows
    (R,) int64, the rows by label, in row order within a label (a stable sort's); grouped
    (R, D) float64, their points; lo, hi (n, D), each label's box, inf / -inf with no row).
    The same as ``np.argsort(labels, kind="stable")`` past the negative labels and a gather,
    in two passes."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    lab = np.ascontiguousarray(labels, dtype=np.int64)
    if pts.ndim != 2 or lab.shape != (len(pts),):
        raise ValueError(f"group_rows: points (M, D) and labels (M,), got {pts.shape}, {lab.shape}")
    return _group_rows(pts, lab, int(n))


@njit(cache=True, nogil=True)
def _rows_by_key(labels: np.ndarray, key_of: np.ndarray, n: int) -> tuple:
    last = key_of.size - 1
    start = np.zeros(n + 1, np.int64)
    for i in range(labels.size):  # counts per key, shifted by one
        k = key_of[labels[i] if labels[i] >= 0 else last]
        if 0 <= k < n:
            start[k + 1] += 1
    for k in range(n):
        start[k + 1] += start[k]
    fill = np.empty(n, np.int64)
    for k in range(n):
        fill[k] = start[k]
    rows = np.empty(start[n], np.int64)
    for i in range(labels.size):  # each row straight to its place, in row order per key
        k = key_of[labels[i] if labels[i] >= 0 else last]
        if 0 <= k < n:
            rows[fill[k]] = i
            fill[k] += 1
    return rows, start


def rows_by_key(labels: np.ndarray, key_of: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``labels`` (M,) int grouped by the key of their label, ``key_of[label]``
    (``key_of`` (L + 1,) int, its last entry the key of label -1), keys 0..n-1 only (others
    left out): (rows (R,) int64 by key, in row order within a key; start (n + 1,) int64, each
    key's run). The same as a stable argsort of the keys below n and its searchsorted
    bounds, in two passes without the (M,) keys."""
    lab = np.ascontiguousarray(labels)
    key = np.ascontiguousarray(key_of, dtype=np.int64)
    if lab.ndim != 1 or key.ndim != 1 or len(key) < 1:
        raise ValueError("rows_by_key: labels (M,) and key_of (L + 1,)")
    if len(lab) and (lab.max() >= len(key) - 1 or lab.min() < -1):
        raise ValueError("rows_by_key: a label has no key")
    return _rows_by_key(lab, key, int(n))


@njit(cache=True, nogil=True)
def _run_sums(points: np.ndarray, begin: np.ndarray, end: np.ndarray) -> np.ndarray:
    out = np.zeros((len(begin), points.shape[1]))
    for j in range(len(begin)):
        if end[j] <= begin[j]:
            continue
        for a in range(points.shape[1]):
            acc = points[begin[j], a]  # the first value, then left to right: cumsum's order
            for i in range(begin[j] + 1, end[j]):
                acc += points[i, a]
            out[j, a] = acc
    return out


def run_sums(points: np.ndarray, begin: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(C, D) float64 sums of the rows ``begin[c]:end[c]`` of ``points`` (P, D), each column
    added left to right from its first value: ``np.cumsum(points[b:e], axis=0)[-1]`` to the
    bit (0 for an empty run). Raises ValueError on runs outside the rows."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    lo = np.ascontiguousarray(begin, dtype=np.int64)
    hi = np.ascontiguousarray(end, dtype=np.int64)
    if pts.ndim != 2 or lo.ndim != 1 or lo.shape != hi.shape:
        raise ValueError(f"run_sums: points (P, D), begin and end (C,); got {pts.shape}")
    if len(lo) and (lo.min() < 0 or hi.max() > len(pts)):
        raise ValueError("run_sums: each run must lie within the rows")
    return _run_sums(pts, lo, hi)


@warmer
def _warm() -> None:
    rows_at_ranks(np.array([0, -1, 0]), np.array([1]), np.array([0, 1]))
    label_boxes(np.zeros((2, 3)), np.array([0, -1]), 1)
    group_rows(np.zeros((2, 3)), np.array([0, -1]), 1)
    run_sums(np.zeros((2, 3)), np.array([0]), np.array([2]))
    for dtype in (np.int32, np.int64):  # segmentation labels are int32; others int64
        rows_by_key(np.array([0, -1], dtype), np.array([0, 1]), 1)
