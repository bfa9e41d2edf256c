"""Packed voxel key -> store slot: an open-addressing hash table in numpy arrays, looked up
by compiled code (`supportnode.kernels.voxelstore`, `supportnode.kernels.rays`)."""

from __future__ import annotations

import numpy as np

from supportnode.kernels.voxelstore import find_slots, mark_blocks
from supportnode.map.keys import _EMPTY, _GOLDEN, _OFFS, _SHIFTS, _TOMB

_SHIFT_ARR = np.array(_SHIFTS, np.int64)
_MASKS = 2 * _OFFS - 1  # each packed field's mask (its width is that of 2 * offset)


class KeyHash:
    """Packed voxel key -> slot, open addressing with linear probing in numpy arrays.

    Lookups are compiled (one probe chain per query); insertion and deletion are vectorised
    over their queries, the Python loop running once per probe step (a handful at load <=
    1/2). Deleted entries become tombstones; the table is rebuilt (O(size), amortised over at
    least as many insertions) when entries plus tombstones pass half of it, so a probe chain
    always ends at an empty entry.
    """

    def __init__(self, capacity: int = 1 << 12) -> None:
        self._alloc(max(1 << 4, 1 << int(np.ceil(np.log2(capacity)))))
        self.size = 0

    def _alloc(self, capacity: int) -> None:
        self.keys = np.full(capacity, _EMPTY, dtype=np.int64)
        self.vals = np.zeros(capacity, dtype=np.int64)
        self.tombs = 0
        self._shift = np.uint64(64 - int(np.log2(capacity)))
        # Occupied blocks of voxels, two bits per entry (`kernels.voxelstore.mark_blocks`).
        self.blocks = np.zeros(max(capacity // 4, 8), dtype=np.uint8)

    @property
    def capacity(self) -> int:
        return len(self.keys)

    def _home(self, q: np.ndarray) -> np.ndarray:
        # Views, not copies: packed keys are non-negative and the shifted hash fits in int64.
        h = np.ascontiguousarray(q, dtype=np.int64).view(np.uint64) * _GOLDEN
        h >>= self._shift
        return h.view(np.int64)

    def _locate(self, q: np.ndarray) -> np.ndarray:
        """Table position of each (Q,) packed key, -1 where absent."""
        out = np.full(len(q), -1, dtype=np.int64)
        pos = self._home(q)
        # First probe on everything; most queries (ray samples in free space) stop here.
        k = self.keys[pos]
        hit = k == q
        out[hit] = pos[hit]
        idx = np.flatnonzero(~hit & (k != _EMPTY))
        mask = self.capacity - 1
        pos = (pos[idx] + 1) & mask
        while idx.size:
            k = self.keys[pos]
            hit = k == q[idx]
            out[idx[hit]] = pos[hit]
            go_on = ~hit & (k != _EMPTY)  # tombstones do not end a probe chain
            idx, pos = idx[go_on], (pos[go_on] + 1) & mask
        return out

    @property
    def table(self) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
        """(keys, vals, shift, block bitmap): what the compiled lookups take."""
        return self.keys, self.vals, int(self._shift), self.blocks

    def find(self, q: np.ndarray) -> np.ndarray:
        """Slot of each (Q,) packed key, -1 where absent."""
        return find_slots(self.keys, self.vals, int(self._shift), q)

    def insert(self, q: np.ndarray, vals: np.ndarray) -> None:
        """Insert (Q,) distinct packed keys that are not in the table, with their slots."""
        if len(q) == 0:
            return
        if 2 * (self.size + self.tombs + len(q)) > self.capacity:
            self._rebuild(self.size + len(q))
        idx = np.arange(len(q))
        pos = self._home(q)
        mask = self.capacity - 1
        while idx.size:
            k = self.keys[pos]
            free = k < 0
            ci, cp = idx[free], pos[free]
            # Several queries may claim one free position: one write wins, read back to see which.
            self.keys[cp] = q[ci]
            won = self.keys[cp] == q[ci]
            self.vals[cp[won]] = vals[ci[won]]
            self.tombs -= int((k[free][won] == _TOMB).sum())
            idx = np.concatenate([idx[~free], ci[~won]])
            pos = (np.concatenate([pos[~free], cp[~won]]) + 1) & mask
        self.size += len(q)
        mark_blocks(self.blocks, q, _SHIFT_ARR, _MASKS)

    def delete(self, q: np.ndarray) -> None:
        """Remove (Q,) distinct packed keys that are in the table."""
        pos = self._locate(q)
        pos = pos[pos >= 0]
        self.keys[pos] = _TOMB
        self.size -= len(pos)
        self.tombs += len(pos)

    def _rebuild(self, live: int) -> None:
        keep = self.keys >= 0
        keys, vals = self.keys[keep], self.vals[keep]
        self._alloc(max(1 << 4, 1 << int(np.ceil(np.log2(4 * max(live, 1))))))
        self.size = 0
        self.insert(keys, vals)
