"""The map's kept points: each voxel's free places filled with evenly spaced picks of a scan's
points in it, in one compiled pass (the numpy path's repeats and fancy-indexed scatters cost
8 ms on a first scan of 25,000 new voxels). Releases the interpreter lock."""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["fill_places", "kept_points", "off_plane"]


@njit(cache=True, nogil=True)
def _fill(slots, counts, starts, lx, ly, lz, keys, size, raw, pts, raw_n):
    k = raw.shape[1]
    filled = 0
    for v in range(slots.size):
        s = slots[v]
        have = raw_n[s]
        room = k - have
        c = counts[v]
        if room <= 0 or c <= 0:
            continue
        take = min(c, room)
        for j in range(take):
            pick = starts[v] + (j * c) // take  # evenly spaced, the first point first
            at = have + j
            raw[s, at, 0] = np.float32(lx[pick])
            raw[s, at, 1] = np.float32(ly[pick])
            raw[s, at, 2] = np.float32(lz[pick])
            # The corner (float64) plus the kept float32 offset, as the numpy path adds them.
            for a in range(3):
                pts[s, at, a] = keys[s, a] * size + np.float64(raw[s, at, a])
        raw_n[s] = have + take
        filled += 1
    return filled


def fill_places(
    slots: np.ndarray,
    counts: np.ndarray,
    starts: np.ndarray,
    local: list[np.ndarray],
    keys: np.ndarray,
    size: float,
    raw: np.ndarray,
    pts: np.ndarray,
    raw_n: np.ndarray,
) -> int:
    """Fill the free places of the voxels at store ``slots`` (V,) int64 with picks of their
    scan points; returns how many voxels took points.

    counts, starts (V,) int64: each voxel's points are ``local[a][starts : starts + counts]``
    (three (N,) float64 columns, offsets from the corner, m). A voxel with ``raw_n[s]`` of its
    K places filled takes ``min(count, K - raw_n[s])`` points, those at ranks
    ``j * count // take``. Writes, in place: raw (S, K, 3) float32 offsets, pts (S, K, 3)
    float64 map-frame points (``keys`` (S, 3) int64 * ``size`` m + offset), raw_n (S,) int32."""
    if not (raw.dtype == np.float32 and pts.dtype == np.float64 and raw_n.dtype == np.int32):
        raise ValueError("raw must be float32, pts float64 and raw_n int32")
    if raw.shape != pts.shape or raw.ndim != 3 or raw.shape[2] != 3:
        raise ValueError(f"raw {raw.shape} and pts {pts.shape} must be one (S, K, 3) shape")
    slots = np.ascontiguousarray(slots, np.int64)
    counts = np.ascontiguousarray(counts, np.int64)
    starts = np.ascontiguousarray(starts, np.int64)
    if not (len(slots) == len(counts) == len(starts)):
        raise ValueError("slots, counts and starts must have one length")
    lx, ly, lz = (np.ascontiguousarray(c, np.float64) for c in local)
    return int(_fill(slots, counts, starts, lx, ly, lz, keys, float(size), raw, pts, raw_n))


@njit(cache=True, nogil=True)
def _kept(pts, raw_n):
    total = 0
    for s in range(raw_n.size):
        total += raw_n[s]
    out = np.empty((total, 3))
    row = 0
    for s in range(raw_n.size):
        for j in range(raw_n[s]):
            out[row, 0] = pts[s, j, 0]
            out[row, 1] = pts[s, j, 1]
            out[row, 2] = pts[s, j, 2]
            row += 1
    return out


def kept_points(pts: np.ndarray, raw_n: np.ndarray) -> np.ndarray:
    """Every slot's kept points, slot by slot and in place order: (P, 3) float64 from pts
    (S, K, 3) float64 and the filled places raw_n (S,) int32 (a dead slot has none), one
    copy without an index array (the numpy path's mask and gather of a map of 400k voxels
    took 15 ms a detection)."""
    if pts.ndim != 3 or pts.shape[2] != 3 or raw_n.shape != pts.shape[:1]:
        raise ValueError(f"pts must be (S, K, 3) and raw_n (S,), got {pts.shape}, {raw_n.shape}")
    if raw_n.size and (raw_n.min() < 0 or raw_n.max() > pts.shape[1]):
        raise ValueError(f"raw_n must lie in [0, {pts.shape[1]}]")
    return _kept(pts, raw_n)


@njit(cache=True, nogil=True)
def _off_plane(raw, slots, raw_n, normal, level, dist, most):
    k = raw.shape[1]
    for v in range(slots.size):
        s = slots[v]
        n0, n1, n2, e = normal[v, 0], normal[v, 1], normal[v, 2], level[v]
        for j in range(k):
            d = 0.0
            if j < raw_n[s]:
                # numpy's order: x n0, + y n1, + z n2, - level, in float64.
                d = np.float64(raw[s, j, 0]) * n0
                d = d + np.float64(raw[s, j, 1]) * n1
                d = d + np.float64(raw[s, j, 2]) * n2
                d = abs(d - e)
            dist[v, j] = d
            # np.maximum's: a NaN wins.
            if j == 0 or d > most[v] or d != d:
                most[v] = d


def off_plane(
    raw: np.ndarray, slots: np.ndarray, raw_n: np.ndarray, normal: np.ndarray, level: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """How far the kept points of the voxels at store ``slots`` (V,) lie off a plane each:
    (V, K) metres, ``|raw . normal - level|`` (0 for a place not filled), and its largest
    per voxel (V,). raw (S, K, 3) float32 offsets from the corners, raw_n (S,) int32 filled
    places, normal (V, 3) float64, level (V,) float64 (the plane's ``p . normal`` in the same
    corner frame). The numpy path's operations in its order: the same bits."""
    if raw.ndim != 3 or raw.shape[2] != 3 or raw_n.shape != raw.shape[:1]:
        raise ValueError(f"raw must be (S, K, 3) and raw_n (S,), got {raw.shape}, {raw_n.shape}")
    slots = np.ascontiguousarray(slots, np.int64)
    normal = np.ascontiguousarray(normal, np.float64)
    level = np.ascontiguousarray(level, np.float64)
    if normal.shape != (len(slots), 3) or level.shape != (len(slots),):
        raise ValueError("normal must be (V, 3) and level (V,) for V slots")
    if len(slots) and (slots.min() < 0 or slots.max() >= len(raw)):
        raise ValueError("slots outside the store")
    dist = np.empty((len(slots), raw.shape[1]))
    most = np.zeros(len(slots))
    _off_plane(raw, slots, raw_n, normal, level, dist, most)
    return dist, most


@warmer
def _warm() -> None:
    kept_points(np.zeros((2, 4, 3)), np.array([1, 0], np.int32))
    off_plane(
        np.zeros((2, 4, 3), np.float32),
        np.array([1]),
        np.array([1, 2], np.int32),
        np.ones((1, 3)),
        np.zeros(1),
    )
    raw = np.zeros((2, 4, 3), np.float32)
    col = np.array([0.01, 0.02, 0.03])
    fill_places(
        np.array([1, 0]),
        np.array([2, 1]),
        np.array([0, 2]),
        [col, col, col],
        np.zeros((2, 3), np.int64),
        0.05,
        raw,
        np.zeros((2, 4, 3)),
        np.zeros(2, np.int32),
    )
