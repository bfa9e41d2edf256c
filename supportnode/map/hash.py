"""Packed voxel key -> store slot: an open-addressing hash table in numpy arrays."""

from __future__ import annotations

import numpy as np

from supportnode.map.keys import _EMPTY, _GOLDEN, _TOMB

_FILTER_BITS = 3  # KeyHash.filter has 2^3 cells per table position


class KeyHash:
    """Packed voxel key -> slot, open addressing with linear probing in numpy arrays.

    Every operation is vectorised over its queries; the Python loop runs once per probe step
    (a handful at load <= 1/2). Deleted entries become tombstones; the table is rebuilt (O(size),
    amortised over at least as many insertions) when entries plus tombstones pass half of it.

    Alongside, ``filter`` counts the live keys per cell of a finer hash (2^_FILTER_BITS cells
    per table position, uint8, saturating at 255: a saturated cell stays "maybe" until the next
    rebuild). A zero cell proves a key absent: at 1/16 or less of the cells occupied it drops
    most absent queries with one lookup, where the table itself leaves up to half of them to
    probe on (:meth:`maybe_present`).
    """

    def __init__(self, capacity: int = 1 << 12) -> None:
        self._alloc(max(1 << 4, 1 << int(np.ceil(np.log2(capacity)))))
        self.size = 0

    def _alloc(self, capacity: int) -> None:
        self.keys = np.full(capacity, _EMPTY, dtype=np.int64)
        self.vals = np.zeros(capacity, dtype=np.int64)
        self.tombs = 0
        self._shift = np.uint64(64 - int(np.log2(capacity)))
        self.filter = np.zeros(capacity << _FILTER_BITS, dtype=np.uint8)
        self._fshift = np.uint64(64 - int(np.log2(capacity)) - _FILTER_BITS)

    @property
    def capacity(self) -> int:
        return len(self.keys)

    def _home(self, q: np.ndarray, shift: np.uint64 | None = None) -> np.ndarray:
        # Views, not copies: packed keys are non-negative and the shifted hash fits in int64.
        h = np.ascontiguousarray(q, dtype=np.int64).view(np.uint64) * _GOLDEN
        h >>= self._shift if shift is None else shift
        return h.view(np.int64)

    def _count(self, q: np.ndarray, sign: int) -> None:
        """Add ``sign`` (+-1) to the filter cells of (Q,) distinct packed keys."""
        cells, n = np.unique(self._home(q, self._fshift), return_counts=True)
        c = self.filter[cells].astype(np.int64)
        self.filter[cells] = np.where(c == 255, 255, np.clip(c + sign * n, 0, 255))

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

    def find(self, q: np.ndarray) -> np.ndarray:
        """Slot of each (Q,) packed key, -1 where absent."""
        pos = self._locate(q)
        return np.where(pos >= 0, self.vals[np.maximum(pos, 0)], -1)

    def maybe_present(self, q: np.ndarray) -> np.ndarray:
        """Indices into (Q,) packed keys of those that may be present (the others are not):
        one lookup in ``filter`` per query, for many queries of which few are present (ray
        samples in free space); :meth:`find_present` settles the rest."""
        # Compared to zero first: numpy finds the nonzero entries of bool 5x faster than uint8.
        return np.flatnonzero(np.take(self.filter, self._home(q, self._fshift)) != 0)

    def find_present(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Indices into (Q,) packed keys of those present, ascending, and their slots.

        Unlike :meth:`find`, no (Q,) result: suits queries of which few are present."""
        idx = np.arange(len(q))
        pos = self._home(q)
        mask = self.capacity - 1
        hits, hit_pos = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        while idx.size:
            k = np.take(self.keys, pos)
            hit = k == q[idx]
            hits.append(idx[hit])
            hit_pos.append(pos[hit])
            go_on = ~hit & (k != _EMPTY)  # tombstones do not end a probe chain
            idx, pos = idx[go_on], (pos[go_on] + 1) & mask
        found, at = np.concatenate(hits), np.concatenate(hit_pos)
        order = np.argsort(found, kind="stable")
        return found[order], self.vals[at[order]]

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
        self._count(q, 1)

    def delete(self, q: np.ndarray) -> None:
        """Remove (Q,) distinct packed keys that are in the table."""
        pos = self._locate(q)
        self._count(q[pos >= 0], -1)
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
