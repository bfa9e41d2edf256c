"""The voxel store's compiled key lookup and ray march against brute force (dicts and
per-sample numpy), including empty input, one voxel, keys at the coordinate limits, and
NaN rejected before the kernel."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.errors import InputError
from supportnode.kernels.rays import ray_voxels
from supportnode.kernels.voxelstore import find_slots
from supportnode.map import KeyHash, VoxelMap, pack_keys
from supportnode.map.keys import _OFFS, _SHIFTS
from supportnode.params import MapParams

_SHIFT_ARR = np.array(_SHIFTS, np.int64)
_LIMIT = _OFFS - 1  # the largest |key| per axis the packing holds


def _table(keys: np.ndarray, slots: np.ndarray, delete: np.ndarray | None = None) -> KeyHash:
    h = KeyHash(capacity=4)
    h.insert(keys, slots)
    if delete is not None and len(delete):
        h.delete(delete)
    return h


key_arrays = st.lists(
    st.tuples(
        st.integers(-int(_LIMIT[0]), int(_LIMIT[0])),
        st.integers(-int(_LIMIT[1]), int(_LIMIT[1])),
        st.integers(-int(_LIMIT[2]), int(_LIMIT[2])),
    ),
    min_size=0,
    max_size=200,
    unique=True,
)


@settings(max_examples=80, deadline=None)
@given(keys=key_arrays, n_absent=st.integers(0, 50), n_deleted=st.integers(0, 30))
def test_find_slots_matches_a_dict(keys, n_absent, n_deleted):
    rng = np.random.default_rng(len(keys) + 7 * n_absent)
    k = np.array(keys, np.int64).reshape(-1, 3)
    packed = pack_keys(k)
    slots = rng.permutation(len(packed)).astype(np.int64)
    gone = packed[: min(n_deleted, len(packed))]
    h = _table(packed, slots, gone)
    want = {int(p): int(s) for p, s in zip(packed, slots, strict=True)}
    for p in gone:
        del want[int(p)]
    absent = pack_keys(rng.integers(-1000, 1000, (n_absent, 3)))
    q = np.concatenate([packed, absent])
    got = find_slots(h.keys, h.vals, int(h._shift), q)
    assert got.tolist() == [want.get(int(p), -1) for p in q]


def test_find_slots_empty_one_voxel_and_the_coordinate_limits():
    h = _table(np.zeros(0, np.int64), np.zeros(0, np.int64))
    assert find_slots(h.keys, h.vals, int(h._shift), np.zeros(0, np.int64)).shape == (0,)
    corners = np.array([_LIMIT, -_LIMIT, [_LIMIT[0], -_LIMIT[1], 0]], np.int64)
    h = _table(pack_keys(corners[:1]), np.array([5]))
    assert find_slots(h.keys, h.vals, int(h._shift), pack_keys(corners)).tolist() == [5, -1, -1]
    h = _table(pack_keys(corners), np.array([1, 2, 3]))
    assert find_slots(h.keys, h.vals, int(h._shift), pack_keys(corners)).tolist() == [1, 2, 3]
    with pytest.raises(InputError):
        pack_keys(corners + [1, 0, 0])  # beyond the limit: refused before any kernel


def test_find_slots_rejects_bad_tables_and_keys():
    h = _table(np.array([1, 2], np.int64), np.array([0, 1], np.int64))
    with pytest.raises(ValueError, match="capacity"):
        find_slots(h.keys, h.vals, int(h._shift) + 1, np.array([1]))
    with pytest.raises(ValueError, match="non-negative"):
        find_slots(h.keys, h.vals, int(h._shift), np.array([-3]))
    with pytest.raises(ValueError, match="int64"):
        find_slots(h.keys.astype(np.int32), h.vals, int(h._shift), np.array([1]))


def _reference_march(origin, u, n, size, stored: dict, last_scan, scan):
    """Per ray, per sample: numpy floor of the sample's voxel, a dict lookup."""
    out = set()
    for r in range(len(n)):
        prev = None
        for j in range(int(n[r])):
            t = (j + 0.5) * size
            key = tuple(math.floor((t * u[r, a] + origin[a]) / size) for a in range(3))
            if key == prev:
                continue
            prev = key
            s = stored.get(key)
            if s is not None and last_scan[s] != scan:
                out.add((r, s))
    return out


@settings(max_examples=60, deadline=None)
@given(
    n_rays=st.integers(0, 40),
    n_vox=st.integers(0, 120),
    size=st.sampled_from([0.05, 0.2, 1.0]),
    far=st.sampled_from([0.0, 1e3, -1.2e4]),
    seed=st.integers(0, 10_000),
)
def test_ray_voxels_matches_a_per_sample_reference(n_rays, n_vox, size, far, seed):
    rng = np.random.default_rng(seed)
    origin = far + rng.normal(0.0, 1.0, 3)
    u = rng.normal(size=(n_rays, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    n = rng.integers(0, 40, n_rays)
    # Stored voxels where the rays go (and elsewhere), some hit by this scan.
    near = [
        np.floor((origin + u[r] * (j + 0.5) * size) / size).astype(np.int64)
        for r in range(n_rays)
        for j in rng.integers(0, max(int(n[r]), 1), 3)
    ]
    cand = np.array(
        near + [np.floor(origin / size) + rng.integers(-20, 20, 3) for _ in range(n_vox)]
    )
    keys = (
        np.unique(cand.reshape(-1, 3).astype(np.int64), axis=0)
        if len(cand)
        else np.zeros((0, 3), np.int64)
    )
    slots = np.arange(len(keys), dtype=np.int64)
    last_scan = rng.integers(0, 3, len(keys)).astype(np.int64)
    h = _table(pack_keys(keys), slots)
    rays, got = ray_voxels(origin, u, n, size, h.table, _OFFS, _SHIFT_ARR, last_scan, 2)
    stored = {tuple(k): int(s) for k, s in zip(keys.tolist(), slots, strict=True)}
    want = _reference_march(origin, u, n, size, stored, last_scan, 2)
    pairs = list(zip(rays.tolist(), got.tolist(), strict=True))
    assert len(pairs) == len(set(pairs))  # each (ray, voxel) once
    assert set(pairs) == want


def test_ray_voxels_empty_and_bad_input():
    h = _table(np.zeros(0, np.int64), np.zeros(0, np.int64))
    table = h.table
    rays, slots = ray_voxels(
        np.zeros(3), np.zeros((0, 3)), np.zeros(0), 0.05, table, _OFFS, _SHIFT_ARR,
        np.zeros(0, np.int64), 1,
    )  # fmt: skip
    assert rays.shape == slots.shape == (0,)
    bad = np.array([[np.nan, 0.0, 1.0]])
    with pytest.raises(ValueError, match="finite"):
        ray_voxels(
            np.zeros(3),
            bad,
            np.array([2]),
            0.05,
            table,
            _OFFS,
            _SHIFT_ARR,
            np.zeros(1, np.int64),
            1,
        )
    with pytest.raises(ValueError, match="sample counts"):
        ray_voxels(
            np.zeros(3),
            np.ones((1, 3)),
            np.array([2, 3]),
            0.05,
            table,
            _OFFS,
            _SHIFT_ARR,
            np.zeros(1, np.int64),
            1,
        )


def test_nan_points_never_reach_the_map_kernels():
    """The map skips non-finite points before voxelizing, so no NaN reaches a kernel."""
    m = VoxelMap(MapParams())
    pts = np.array([[1.0, 0.0, 0.0], [np.nan, 0.0, 0.0], [1.01, 0.0, 0.0], [np.inf, 1, 1]])
    t = m.integrate(pts, np.eye(4), 0.0)
    assert m.stats()["points_invalid"] == 2 and len(t.keys) == 1 and len(m) == 1
