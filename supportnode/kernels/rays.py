"""Ray clearing's march: the stored voxels a scan's rays pass through.

A ray from ``origin`` along unit direction u is sampled at ``t = (j + 0.5) * size`` for
j < n (one sample per voxel edge); each sample's voxel key ``floor((origin + u t) / size)`` is
packed like the map's keys (``offs``, ``shifts``: per axis, the offset and bit shift) and
looked up in the voxel store's key table (`supportnode.kernels.voxelstore`). Consecutive
samples of a ray in one voxel count once (per axis the key is monotone along a ray, so a ray
never comes back to a voxel it left). Releases the interpreter lock.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer
from supportnode.kernels.voxelstore import EMPTY, _block_bit, _check_table, _lookup

__all__ = ["ray_voxels"]


@njit(cache=True, nogil=True)
def _ray_voxels(origin, u, n, size, keys, vals, shift, bits, offs, shifts, last_scan, scan):
    bshift = 64 - int(np.log2(bits.size * 8))
    total = 0
    for r in range(n.size):
        total += n[r]
    rays = np.empty(min(total, 1 << 20), np.int64)
    slots = np.empty(rays.size, np.int64)
    m = 0
    for r in range(n.size):
        prev = -1
        for j in range(n[r]):
            t = (j + 0.5) * size
            fx = math.floor((t * u[r, 0] + origin[0]) / size) + offs[0]
            fy = math.floor((t * u[r, 1] + origin[1]) / size) + offs[1]
            fz = math.floor((t * u[r, 2] + origin[2]) / size) + offs[2]
            inside = 0 <= fx < 2 * offs[0] and 0 <= fy < 2 * offs[1] and 0 <= fz < 2 * offs[2]
            packed = (fx << shifts[0]) | (fy << shifts[1]) | (fz << shifts[2])
            if not inside or packed == prev:
                prev = packed if inside else -1
                continue
            prev = packed
            b = _block_bit(fx, fy, fz, shifts, bshift)
            if not (bits[b >> 3] >> (b & 7)) & 1:
                continue  # most samples: free space, no table access
            s = _lookup(keys, vals, shift, packed)
            if s < 0 or last_scan[s] == scan:  # absent, or hit by this scan: seen, kept
                continue
            if m == rays.size:
                rays = _grow(rays)
                slots = _grow(slots)
            rays[m] = r
            slots[m] = s
            m += 1
    return rays[:m].copy(), slots[:m].copy()


@njit(cache=True, nogil=True)
def _grow(a):
    out = np.empty(2 * a.size, a.dtype)
    for i in range(a.size):  # a loop: slice assignment compiles for seconds on a fresh install
        out[i] = a[i]
    return out


def ray_voxels(
    origin: np.ndarray,
    u: np.ndarray,
    n: np.ndarray,
    size: float,
    table: tuple[np.ndarray, np.ndarray, int, np.ndarray],
    offs: np.ndarray,
    shifts: np.ndarray,
    last_scan: np.ndarray,
    scan: int,
) -> tuple[np.ndarray, np.ndarray]:
    """(ray index, store slot) pairs, (M,) int64 each, of the stored voxels that the rays
    pass through and that scan number ``scan`` did not hit (``last_scan[slot] != scan``).

    origin (3,) metres; u (R, 3) unit directions; n (R,) int64 samples per ray; size: voxel
    edge, metres; table: (keys, vals, shift, block bitmap) of the key table
    (`supportnode.map.hash.KeyHash.table`); offs, shifts (3,) int64: the
    key packing; last_scan (S,) int64 per store slot. Finite input only."""
    origin = np.ascontiguousarray(origin, dtype=np.float64).reshape(3)
    u = np.ascontiguousarray(u, dtype=np.float64).reshape(-1, 3)
    n = np.ascontiguousarray(n, dtype=np.int64).reshape(-1)
    if len(n) != len(u):
        raise ValueError(f"{len(u)} directions but {len(n)} sample counts")
    if not (np.isfinite(origin).all() and np.isfinite(u).all()):
        raise ValueError("origin and directions must be finite")
    if not (math.isfinite(size) and size > 0):
        raise ValueError(f"voxel size must be positive and finite, got {size}")
    if len(n) and n.min() < 0:
        raise ValueError("sample counts must be >= 0")
    keys, vals, shift, bits = table
    shift = _check_table(keys, vals, shift)
    if bits.dtype != np.uint8 or bits.size == 0 or bits.size & (bits.size - 1):
        raise ValueError("the block bitmap must be a non-empty uint8 array of 2^k bytes")
    offs = np.ascontiguousarray(offs, dtype=np.int64).reshape(3)
    shifts = np.ascontiguousarray(shifts, dtype=np.int64).reshape(3)
    last_scan = np.ascontiguousarray(last_scan, dtype=np.int64)
    return _ray_voxels(
        origin, u, n, float(size), keys, vals, shift, bits, offs, shifts, last_scan, int(scan)
    )


@warmer
def _warm() -> None:
    keys = np.full(16, EMPTY, np.int64)
    ray_voxels(
        np.zeros(3),
        np.array([[1.0, 0.0, 0.0]]),
        np.array([3]),
        0.05,
        (keys, np.zeros(16, np.int64), 60, np.zeros(4, np.uint8)),
        np.array([1 << 21, 1 << 21, 1 << 18]),
        np.array([41, 19, 0]),
        np.zeros(4, np.int64),
        1,
    )
