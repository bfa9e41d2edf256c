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

__all__ = ["EMPTY", "GOLDEN", "TOMB", "find_slots", "home"]

EMPTY, TOMB = -1, -2
GOLDEN = 0x9E3779B97F4A7C15


@njit(cache=True, nogil=True, inline="always")
def _home(key: int, shift: int) -> int:
    # All in uint64 (mixing it with int64 makes float64 in numba), then back to int64.
    return int64((uint64(key) * uint64(GOLDEN)) >> uint64(shift))


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
