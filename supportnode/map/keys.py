"""Voxel keys packed into one int64: the map's coordinate range and its packing."""

from __future__ import annotations

import numpy as np

from supportnode.errors import InputError

# Keys are packed into one non-negative int64: 22 bits for x and y, 19 for z, each around an
# offset of half its range: |x|, |y| < 2^21 voxels (+-105 km at 5 cm), |z| < 2^18 (+-13 km).
_BITS_XY, _BITS_Z = 22, 19
_OFFS = np.array([1 << (_BITS_XY - 1), 1 << (_BITS_XY - 1), 1 << (_BITS_Z - 1)], np.int64)
_SHIFTS = (_BITS_XY + _BITS_Z, _BITS_Z, 0)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: scatters spatially close keys
_EMPTY, _TOMB = -1, -2
_MAGIC = float(1 << 52)  # x + 2^52 holds an integer 0 <= x < 2^52 as its mantissa bits


def pack_keys(keys: np.ndarray) -> np.ndarray:
    """(N, 3) int64 voxel keys -> (N,) non-negative int64; raises InputError out of range."""
    k = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    # Column by column, shifted in place: numpy reduces and combines the short axis of an
    # (N, 3) array several times slower, and (N, 3) temporaries cost their pages.
    out = np.zeros(len(k), np.int64)
    for a in range(3):  # three axes
        col = k[:, a] + _OFFS[a]
        if len(col) and (col.min() < 0 or col.max() >= 2 * _OFFS[a]):
            raise InputError(
                "points too far from the map origin for this voxel size "
                f"(|key| must stay below 2^{_BITS_XY - 1} in x, y and 2^{_BITS_Z - 1} in z)"
            )
        col <<= _SHIFTS[a]
        out |= col
    return out


def coordinate_range(voxel_size: float) -> np.ndarray:
    """(3,) metres: the largest |x|, |y|, |z| a map point may have at this voxel size (what
    :func:`pack_keys` can hold, a voxel short of it)."""
    return (_OFFS - 1).astype(np.float64) * float(voxel_size)


def unpack_keys(packed: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pack_keys`: (N,) int64 -> (N, 3) int64."""
    p = np.asarray(packed, dtype=np.int64)
    cols = [(p >> _SHIFTS[a]) & ((2 * _OFFS[a]) - 1) for a in range(3)]
    return np.stack(cols, axis=1) - _OFFS
