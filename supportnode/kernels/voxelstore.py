"""The voxel store's key table: packed voxel key -> slot, open addressing, linear probing.

The table is three plain arrays owned by `supportnode.map.hash.KeyHash`: ``keys`` (C,) int64
(``EMPTY`` -1, ``TOMB`` -2 for a deleted entry, else a packed key >= 0), ``vals`` (C,) int64
slots, and the home position of a key is ``(key * GOLDEN) >> shift`` (Fibonacci hashing, C a
power of two, ``shift = 64 - log2(C)``). The kernels release the interpreter lock: the node's
detecting thread runs while the receiving thread looks keys up.
"""

from __future__ import annotations

import numpy as np
from numba import int64, njit, uint64

from supportnode.kernels.runtime import warmer

__all__ = ["BLOCK", "EMPTY", "GOLDEN", "TOMB", "find_slots", "home", "mark_blocks"]

# Beside the table, a bitmap of the occupied blocks of BLOCK^3 voxels (a bit per hashed block
# key, set when a key is inserted, cleared only when the table is rebuilt): a clear bit proves
# a key absent. A ray's consecutive samples share a block, and the bitmap (two bits per table
# entry: 32 KB for 131k entries) stays in cache, where the table itself (1 MB) does not:
# ray samples in free space, most of them, cost no table access.
BLOCK_SHIFT = 2
BLOCK = 1 << BLOCK_SHIFT

EMPTY, TOMB = -1, -2
GOLDEN = 0x9E3779B97F4A7C15


@njit(cache=True, nogil=True, inline="always")
def _home(key: int, shift: int):
    # All in uint64 (mixing it with int64 makes float64 in numba), then back to int64.
    return int64((uint64(key) * uint64(GOLDEN)) >> uint64(shift))


@njit(cache=True, nogil=True, inline="always")
def _block_bit(fx: int, fy: int, fz: int, shifts: np.ndarray, bshift: int) -> int:
    """Bit index of the block of a key given by its packed fields (key + offset, >= 0)."""
    b = (
        ((fx >> BLOCK_SHIFT) << shifts[0])
        | ((fy >> BLOCK_SHIFT) << shifts[1])
        | ((fz >> BLOCK_SHIFT) << shifts[2])
    )
    return _home(b, bshift)


@njit(cache=True, nogil=True)
def _mark_blocks(bits: np.ndarray, q: np.ndarray, shifts: np.ndarray, masks: np.ndarray) -> None:
    bshift = 64 - int(np.log2(bits.size * 8))
    for i in range(q.size):
        k = q[i]
        b = _block_bit(
            (k >> shifts[0]) & masks[0], (k >> shifts[1]) & masks[1], k & masks[2], shifts, bshift
        )
        bits[b >> 3] |= np.uint8(1 << (b & 7))


def mark_blocks(bits: np.ndarray, q: np.ndarray, shifts: np.ndarray, masks: np.ndarray) -> None:
    """Set the block bits of (Q,) packed keys in ``bits`` (B,) uint8, B a power of two;
    shifts, masks (3,) int64: each field's bit shift and mask (z's shift is 0)."""
    if bits.dtype != np.uint8 or bits.size == 0 or bits.size & (bits.size - 1):
        raise ValueError("the block bitmap must be a non-empty uint8 array of 2^k bytes")
    q = np.ascontiguousarray(q, dtype=np.int64).reshape(-1)
    _mark_blocks(bits, q, np.asarray(shifts, np.int64), np.asarray(masks, np.int64))


@njit(cache=True, nogil=True)
def _lookup(keys: np.ndarray, vals: np.ndarray, shift: int, q: int) -> int:
    mask = keys.size - 1
    pos = _home(q, shift)
    while True:
        k = keys[pos]
        if k == q:
            return vals[pos]
        if k == EMPTY:
            return -1
        pos = (pos + 1) & mask  # tombstones do not end a probe chain


@njit(cache=True, nogil=True)
def _find_slots(keys: np.ndarray, vals: np.ndarray, shift: int, q: np.ndarray) -> np.ndarray:
    out = np.empty(q.size, np.int64)
    for i in range(q.size):
        out[i] = _lookup(keys, vals, shift, q[i])
    return out


def _check_table(keys: np.ndarray, vals: np.ndarray, shift: int) -> int:
    cap = len(keys)
    if keys.dtype != np.int64 or vals.dtype != np.int64 or vals.shape != keys.shape:
        raise ValueError("table keys and vals must be (C,) int64 arrays of one length")
    if cap == 0 or cap & (cap - 1) or (1 << (64 - int(shift))) != cap:
        raise ValueError(f"table capacity {cap} must be 2^(64 - shift), shift {shift}")
    return int(shift)


def find_slots(keys: np.ndarray, vals: np.ndarray, shift: int, q: np.ndarray) -> np.ndarray:
    """Slot of each (Q,) packed key (int64 >= 0) in the table, -1 where absent: (Q,) int64.
    The table must hold at least one EMPTY entry (a probe chain ends there)."""
    shift = _check_table(keys, vals, shift)
    q = np.ascontiguousarray(q, dtype=np.int64).reshape(-1)
    if len(q) and q.min() < 0:
        raise ValueError("packed keys are non-negative")
    return _find_slots(keys, vals, shift, q)


def home(q: np.ndarray, shift: int) -> np.ndarray:
    """(Q,) int64 home positions of (Q,) packed keys (numpy; the kernels' hash)."""
    h = np.ascontiguousarray(q, dtype=np.int64).view(np.uint64) * np.uint64(GOLDEN)
    h >>= np.uint64(shift)
    return h.view(np.int64)


@warmer
def _warm() -> None:
    keys = np.full(16, EMPTY, np.int64)
    vals = np.zeros(16, np.int64)
    find_slots(keys, vals, 60, np.array([3], np.int64))
    shifts = np.array([41, 19, 0], np.int64)
    masks = np.array([(1 << 22) - 1, (1 << 22) - 1, (1 << 19) - 1], np.int64)
    mark_blocks(np.zeros(8, np.uint8), np.array([3], np.int64), shifts, masks)
