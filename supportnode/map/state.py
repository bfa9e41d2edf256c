"""The fields of `VoxelMap`'s store, declared once for the mixins that work on them."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from supportnode.params import MapParams

if TYPE_CHECKING:
    from supportnode.map.hash import KeyHash


class StoreState:
    """Declarations only (`VoxelMap.__init__` and ``_alloc_store`` set them): per slot, the
    voxel's key, packed key, liveness, point count, moments (sums and outer products, relative
    to the corner), last stamp and scan, evidence, kept points (raw relative to the corner,
    and in the map frame) with their count and ring head."""

    params: MapParams
    size: float
    representation: str
    keep_points: int
    max_evidence: int
    clear_rays: int
    clear_tolerance: float
    crop_slack: float
    age_slack: float
    version: int
    _rng: np.random.Generator
    _hash: KeyHash
    _buffers: dict[str, np.ndarray]
    _stats: dict[str, int]
    _scans: int
    _capacity: int
    _free: np.ndarray
    _nfree: int
    _last_pass: tuple[float, np.ndarray] | None
    _keys: np.ndarray
    _packed: np.ndarray
    _alive: np.ndarray
    _count: np.ndarray
    _moments: np.ndarray
    _sums: np.ndarray
    _outer: np.ndarray
    _last_seen: np.ndarray
    _last_scan: np.ndarray
    _evidence: np.ndarray
    _raw: np.ndarray
    _pts: np.ndarray
    _raw_n: np.ndarray
    _raw_head: np.ndarray
    # The last merged scan's map-frame columns, origin and stamp, until `settle` clears.
    _pending: tuple[list[np.ndarray], np.ndarray, float] | None

    def __len__(self) -> int:
        return self._hash.size

    def _take(self, n: int) -> np.ndarray:
        raise NotImplementedError

    def _remove(self, slots: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def settle(self) -> np.ndarray:
        raise NotImplementedError
