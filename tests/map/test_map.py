"""Incremental voxel map: exact merging, forgetting, free-space clearing, detection through it."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import plane_points

from supportnode.errors import InputError
from supportnode.geometry.voxels import OUTER_INDEX, voxelize
from supportnode.map import KeyHash, VoxelMap, pack_keys, unpack_keys
from supportnode.params import MapParams

EYE = np.eye(4)


def _pose(x=0.0, y=0.0, z=1.0, yaw_deg=0.0):
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    pose = np.eye(4)
    pose[:2, :2] = [[c, -s], [s, c]]
    pose[:3, 3] = [x, y, z]
    return pose


def _by_key(state):
    order = np.lexsort(state["keys"].T[::-1])
    return {k: v[order] for k, v in state.items()}


def _no_clear(**kw):
    return VoxelMap(MapParams(clear_free_space=False, max_age=0.0, **kw))


def test_key_hash_insert_find_delete():
    rng = np.random.default_rng(0)
    keys = np.unique(rng.integers(0, 1 << 50, 50_000))
    h = KeyHash(16)
    h.insert(keys, np.arange(len(keys)))
    assert np.array_equal(h.find(keys), np.arange(len(keys)))
    assert (h.find(keys + (1 << 51)) == -1).all()
    h.delete(keys[::3])
    assert (h.find(keys[::3]) == -1).all()
    rest = np.setdiff1d(np.arange(len(keys)), np.arange(0, len(keys), 3))
    assert np.array_equal(h.find(keys[rest]), rest)
    h.insert(keys[::3], np.arange(0, len(keys), 3))  # tombstones reused
    assert np.array_equal(h.find(keys), np.arange(len(keys)))
    assert h.size == len(keys)


def test_pack_round_trip_and_range():
    k = np.array([[0, 0, 0], [-5, 7, -1], [2**21 - 1, -(2**21), -(2**18)]])
    assert np.array_equal(unpack_keys(pack_keys(k)), k)
    with pytest.raises(InputError):
        pack_keys(np.array([[0, 0, 2**18]]))


def test_merge_is_exact_and_split_invariant(rng):
    a = plane_points(rng, -2, 2, -2, 2, 0.31, 20_000)
    b = plane_points(rng, -1, 3, -1, 3, 0.31, 20_000)
    a[:, 2] += rng.normal(0, 0.004, len(a))
    b[:, 2] += rng.normal(0, 0.004, len(b))
    two = _no_clear()
    two.integrate(a, EYE, 0.0, in_map_frame=True)
    two.integrate(b, EYE, 0.1, in_map_frame=True)
    grid = voxelize(np.r_[a, b], np.full(3, two.size))
    got = _by_key(two.voxels())
    want = _by_key(
        {"keys": grid.keys, "count": grid.counts, "sums": grid.sums, "outer": grid.outer}
    )
    assert np.array_equal(got["keys"], want["keys"])
    assert np.array_equal(got["count"], want["count"])
    np.testing.assert_allclose(got["sums"], want["sums"], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got["outer"], want["outer"], rtol=1e-12, atol=1e-15)

    # The same points in three parts, given in the sensor frame of a moved sensor.
    pose = _pose(0.3, -0.2, 1.1, 25.0)
    parts = _no_clear()
    inv = np.linalg.inv(pose)
    both = np.r_[a, b]
    for i, chunk in enumerate(np.array_split(both, 3)):
        parts.integrate(chunk @ inv[:3, :3].T + inv[:3, 3], pose, 0.1 * i)
    got2 = _by_key(parts.voxels())
    assert np.array_equal(got2["keys"], want["keys"])
    np.testing.assert_allclose(got2["sums"], want["sums"], atol=1e-9)


def _reference_voxels(keys: np.ndarray) -> dict:
    """Integer keys (N, 3) of a scan's points -> {key: indices of its points, input order}."""
    rows: dict = {}
    for i, key in enumerate(map(tuple, keys.tolist())):
        rows.setdefault(key, []).append(i)
    return {key: np.array(idx) for key, idx in rows.items()}


def _reference_picks(count: int, room: int) -> list[int]:
    """Evenly spaced picks of min(count, room) of a voxel's count points, in input order."""
    take = min(count, room)
    return [j * count // take for j in range(take)]


class _Reference:
    """The map's voxels as dicts: count, moments (sums of the offsets from the corner, then of
    their products in OUTER_INDEX order) and kept points (map frame) of each, with the
    "stable" rule: free places are filled from each scan, and a voxel the map renewed (told,
    not decided, here) starts over from the scan's points. The offsets are non-negative: no
    cancellation, so any summation order gives the moments to ~1e-13."""

    def __init__(self, size: float, keep: int) -> None:
        self.size, self.keep = size, keep
        self.count: dict = {}
        self.moments: dict = {}
        self.kept: dict = {}

    def merge(self, pts: np.ndarray, renewed: set, removed: np.ndarray) -> None:
        keys = np.floor(pts / self.size)
        off = pts - keys * self.size
        terms = np.c_[off, np.stack([off[:, a] * off[:, b] for a, b in OUTER_INDEX], axis=1)]
        # Each point as the map keeps it: float32 offset from its corner, then map frame.
        as_kept = keys * self.size + off.astype(np.float32).astype(np.float64)
        for key, idx in _reference_voxels(keys.astype(np.int64)).items():
            self.count[key] = self.count.get(key, 0) + len(idx)
            self.moments[key] = self.moments.get(key, 0.0) + terms[idx].sum(axis=0)
            kept = [] if key in renewed else self.kept.get(key, [])
            room = self.keep - len(kept)
            if room > 0:
                kept = kept + as_kept[idx[_reference_picks(len(idx), room)]].tolist()
            self.kept[key] = kept
        for key in map(tuple, removed.tolist()):
            del self.count[key], self.moments[key], self.kept[key]


def _record_renewals(m: VoxelMap, scan: list) -> list:
    """Wrap the map's see-through test: the keys it renews, scan by scan, each decision
    checked against :func:`_reference_seen_through` on ``scan[0]``, the scan's points."""
    log: list = []
    test = m._seen_through

    def recording(grid, vox, pairs, raw, off, origin, margin):
        through = test(grid, vox, pairs, raw, off, origin, margin)
        want = _reference_seen_through(m.size, scan[0], grid.keys[vox], raw, off, origin, margin)
        assert np.array_equal(through, want)
        log[-1] |= set(map(tuple, grid.keys[vox[through]].tolist()))
        return through

    m._seen_through = recording
    return log


_CLOSED_KITCHEN = """
  - {kind: box, name: wall_front, size: [5.2, 0.1, 2.5], xyz: [0, -2.05, 1.25], role: structure}
  - {kind: box, name: ceiling, size: [5.2, 4.2, 0.05], xyz: [0, 0, 2.525], role: structure}
"""


def _kitchen_scans(n: int, noise=None, seed: int = 3):
    """n scans of the kitchen closed on all sides by a 48-beam lidar (34,560 points each)."""
    from supportnode.sim import Lidar, parse_scene, poses_for
    from supportnode.sim.scene import scene_path
    from supportnode.sim.simulate import scans

    scene = parse_scene(scene_path("kitchen").read_text(encoding="utf-8") + _CLOSED_KITCHEN)
    lidar = Lidar(48, -22.5, 22.5, 720, 0.3, 30.0, 10.0)
    return scans(scene, lidar, poses_for(scene, n), seed=seed, noise=noise)


def _check_against_reference(m: VoxelMap, scans) -> list[int]:
    """Integrate (points, pose) scans (map frame) into m and compare it, after each, with
    :class:`_Reference`, and every renewal decision with :func:`_reference_seen_through`;
    returns the number of voxels each scan hit."""
    ref = _Reference(m.size, m.keep_points)
    current: list = [None]  # the scan being merged, for the see-through reference
    renewals = _record_renewals(m, current)
    merged, sizes = 0, []
    for i, (pts, pose) in enumerate(scans):
        renewals.append(set())
        good = pts[np.isfinite(pts).all(axis=1)]
        current[0] = good
        touched = m.integrate(pts, pose, 0.1 * i, in_map_frame=True)
        merged += len(good)
        sizes.append(len(touched.keys))
        ref.merge(good, renewals[-1], touched.removed)

        state = m.voxels()
        keys = list(map(tuple, state["keys"].tolist()))
        assert len(keys) == len(ref.count) and set(keys) == set(ref.count)
        assert [ref.count[k] for k in keys] == state["count"].tolist()
        # The moments of the voxels this scan hit (the others' did not change).
        hit = m.voxels(touched.keys)
        got = np.c_[hit["sums"], hit["outer"]]
        want = np.array([ref.moments[k] for k in map(tuple, hit["keys"].tolist())])
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
        # Every voxel's kept points, in the order of the keys asked for.
        want_pts = np.array([p for k in keys for p in ref.kept[k]]).reshape(-1, 3)
        assert np.array_equal(m.points(state["keys"]), want_pts), i
    st = m.stats()
    assert st["voxels"] == len(ref.count) and st["points_merged"] == merged
    assert st["renewed"] == sum(map(len, renewals))
    return sizes


@pytest.mark.slow
def test_merge_matches_a_per_voxel_reference():
    """Counts, moments and the kept points of every voxel, scan after scan, as a plain
    per-voxel computation has them: moments within 1e-12 (the summation order may differ),
    the kept points the very same raw points (evenly spaced picks in input order among each
    voxel's points), given the renewals; on a noisy sequence (renewals), with a far stray
    return (a box too large for a dense table: sorted keys), one 100 km away (a box of more
    than 2^53 voxels: geometry.voxels.voxelize) and a driver's misses (NaN)."""
    from supportnode.sim.noise import NoiseSpec

    clouds = _kitchen_scans(5, NoiseSpec(gauss=0.01))
    scans = [(c.points.astype(np.float64), c.sensor_pose) for c in clouds]
    far = np.vstack([scans[2][0], [[400.0, -300.0, 1.0]]])
    holes = scans[3][0].copy()
    holes[::97] = np.nan
    very_far = np.vstack([scans[4][0], [[1.0e5, -1.0e5, 5.0e3]]])
    scans = [
        *scans[:2],
        (far, scans[2][1]),
        (holes, scans[3][1]),
        scans[3],
        (very_far, scans[4][1]),
    ]
    m = VoxelMap(MapParams(radius=30.0, max_age=0.0))
    _check_against_reference(m, scans)
    st = m.stats()
    assert st["renewed"] > 0 and st["cleared"] > 0 and st["points_invalid"] > 0


@pytest.mark.slow
def test_merge_of_more_voxels_than_16_bit_ranks_matches_the_reference():
    """Scans of ~67k voxels each (ranks beyond 16 bits sort otherwise): the same as the
    reference, the second scan filling the places the first left free."""
    rng = np.random.default_rng(5)
    pose = _pose(z=1.5)
    scans = [(pose[:3, 3] + rng.uniform(-1.5, 1.5, (80_000, 3)), pose) for _ in range(2)]
    assert min(_check_against_reference(_no_clear(), scans)) > 1 << 16


def _reference_seen_through(size, scan, keys, raw, off, origin, margin) -> np.ndarray:
    """VoxelMap._seen_through by its docstring, one candidate and one ray at a time, from
    the scan's points themselves (scan (N, 3), map frame); keys (C, 3): the candidates."""
    scan_keys = np.floor(scan / size)
    local = scan - scan_keys * size
    points = {k: local[idx] for k, idx in _reference_voxels(scan_keys.astype(np.int64)).items()}
    out = []
    for c, key in enumerate(keys):
        o = origin - key * size
        w = raw[c].astype(np.float64) - o  # (k, 3): the kept points from the sensor
        w2 = w[:, 0] * w[:, 0] + w[:, 1] * w[:, 1] + w[:, 2] * w[:, 2]
        radius2 = np.minimum(0.3 * size, off[c]) ** 2
        before = max(0.5 * size, margin[c])
        seen = False
        for step in itertools.product((-1, 0, 1), repeat=3):
            nb = points.get(tuple((key + step).tolist()))
            if nb is None:
                continue
            for i in _reference_picks(len(nb), 32):  # rays to the neighbour's points
                d = nb[i] + np.array(step) * size - o
                length = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
                u = d * (1.0 / max(length, 1e-12))
                along = w[:, 0] * u[0] + w[:, 1] * u[1] + w[:, 2] * u[2]
                hit = (along > 0) & (w2 - along * along < radius2) & (along < length - before)
                seen |= bool(hit.any())
        out.append(seen)
    return np.array(out, bool)


def test_seen_through_matches_a_per_ray_reference(rng):
    """The renewal test on a real scan's voxels, with kept points scattered around the
    scan's points (some on the rays, some off them), against a per-ray loop."""
    (cloud,) = _kitchen_scans(1, seed=1)
    m = _no_clear()
    cols = [np.ascontiguousarray(cloud.points[:, a], dtype=np.float64) for a in range(3)]
    grid = m._voxelize(cols)
    vox = rng.choice(np.flatnonzero(grid.counts >= 4), 300, replace=False)
    need = np.zeros(len(grid.counts), bool)
    pairs = m._neighbour_pairs(grid, pack_keys(grid.keys), vox)
    need[pairs[1]] = True
    grid = m._by_voxel(grid, need)
    k = m.keep_points
    # Kept points: the scan's own points in the voxel, moved across the rays, and for half
    # of the voxels towards the sensor (the rays to the scan's points then pass through them).
    origin = cloud.sensor_pose[:3, 3]
    raw = np.empty((len(vox), k, 3), np.float32)
    for c, v in enumerate(vox):
        at = grid.starts[v] + rng.integers(0, grid.counts[v], k)
        p = np.stack([grid.local[a][at] for a in range(3)], axis=1)
        to_sensor = origin - (grid.keys[v] * m.size + p)
        lift = rng.uniform(0.03, 0.08) * (c % 2) / np.linalg.norm(to_sensor, axis=1)
        raw[c] = p + lift[:, None] * to_sensor + rng.normal(0.0, 0.005, (k, 3))
    off = rng.uniform(0.0, 0.03, (len(vox), k))
    off[rng.uniform(size=off.shape) < 0.2] = 0.0  # places not filled
    margin = rng.uniform(0.0, 0.05, len(vox))
    got = m._seen_through(grid, vox, pairs, raw, off, origin, margin)
    scan = np.stack(cols, axis=1)
    want = _reference_seen_through(m.size, scan, grid.keys[vox], raw, off, origin, margin)
    assert 0.1 < want.mean() < 0.9  # both outcomes are tested
    assert np.array_equal(got, want)


def test_precise_far_from_origin(rng):
    """Moments relative to each voxel's corner: a plane 100 km away fits as well as near 0."""
    pts = plane_points(rng, 0, 1, 0, 1, 0.02, 5000)
    far = np.array([1.0e5, -4.0e4, 0.0])  # keys ~2e6: needs the 22-bit x, y range
    m0, m1 = _no_clear(), _no_clear()
    m0.integrate(pts, EYE, 0.0, in_map_frame=True)
    m1.integrate(pts + far, _pose(*far), 0.0, in_map_frame=True)
    v0, v1 = m0.voxels(), m1.voxels()
    var0 = v0["outer"][:, 2] / v0["count"] - (v0["sums"][:, 2] / v0["count"]) ** 2
    var1 = v1["outer"][:, 2] / v1["count"] - (v1["sums"][:, 2] / v1["count"]) ** 2
    assert np.abs(var0).max() < 1e-15 and np.abs(var1).max() < 1e-12


def test_crop_radius_age_and_cap(rng):
    params = MapParams(radius=5.0, max_age=1.0, max_voxels=1000, clear_free_space=False)
    m = VoxelMap(params, crop_slack=0.0, age_slack=0.0)
    near = plane_points(rng, -1, 1, -1, 1, 0.0, 2000)  # 1600 voxels of 5 cm: over the cap
    m.integrate(near[:400], _pose(), 0.0, in_map_frame=True)  # old ones
    m.integrate(near[400:], _pose(), 0.5, in_map_frame=True)
    st = m.stats()
    assert st["voxels"] <= 1000 and st["dropped_cap"] > 0
    # The oldest went first: what is left of stamp 0.0 is less than what is left of stamp 0.5.
    seen = m.voxels()["last_seen"]
    assert (seen == 0.5).sum() > 0.9 * st["voxels"]

    m2 = VoxelMap(MapParams(radius=5.0, max_age=1.0, clear_free_space=False), crop_slack=0.0)
    m2.integrate(plane_points(rng, -1, 1, -1, 1, 0.0, 500), _pose(), 0.0, in_map_frame=True)
    m2.integrate(
        plane_points(rng, 5.5, 6.5, -0.5, 0.5, 0.0, 500), _pose(x=3.0), 0.2, in_map_frame=True
    )
    # The sensor moves to x=7: the first patch (x in [-1, 1]) is beyond 5 m, the second not.
    m2.integrate(np.zeros((0, 3)), _pose(x=7.0), 0.4, in_map_frame=True)
    c = (m2.voxels()["keys"][:, :2] + 0.5) * m2.size
    assert np.hypot(c[:, 0] - 7.0, c[:, 1]).max() <= 5.0
    assert m2.stats()["dropped_radius"] > 0 and len(m2) > 200
    # Age: nothing seen since 0.2 s; at 1.3 s everything is older than 1 s.
    n = len(m2)
    assert n > 0
    m2.integrate(np.zeros((0, 3)), _pose(x=7.0), 1.3, in_map_frame=True)
    assert len(m2) == 0 and m2.stats()["dropped_age"] == n


def test_memory_flat_on_an_endless_run(rng):
    """200 scans along a 200 m line: voxels and the store stop growing once the radius fills."""
    m = VoxelMap(MapParams(radius=6.0, max_age=0.0, clear_free_space=False))
    counts, caps = [], []
    for i in range(200):
        x = 1.0 * i
        floor = plane_points(rng, x - 6, x + 6, -6, 6, 0.0, 4000)
        m.integrate(floor, _pose(x=x), 0.1 * i, in_map_frame=True)
        counts.append(len(m))
        caps.append(m.stats()["capacity"])
    # The disc of radius 6 m holds at most pi*6^2/0.05^2 ~ 45k columns (plus crop slack).
    assert max(counts[100:]) < 1.15 * max(counts[20:40])
    assert caps[-1] == caps[60]
    assert m.stats()["dropped_radius"] > 0


SCENE = """
name: removed
primitives:
  - {kind: box, name: floor, size: [16, 16, 0.02], xyz: [0, 0, -0.01], role: surface, surface: floor}
  - {kind: box, name: wall, size: [0.1, 6, 2.0], xyz: [3.0, 0, 1.0], role: structure}
"""
BOX = (
    "  - {kind: box, name: box, size: [0.4, 0.4, 0.5], xyz: [1.5, 0, 0.25], role: object, "
    "object: box}\n"
)


def test_removed_object_is_cleared_and_floor_stays():
    """A box in scans 0-2 and gone from scans 3-7: it leaves the map within a few scans, while
    the floor (under it, around it, and far away at grazing angles) stays."""
    from supportnode.sim import Lidar, parse_scene
    from supportnode.sim.noise import parse_noise
    from supportnode.sim.simulate import finish

    with_box, without = parse_scene(SCENE + BOX), parse_scene(SCENE)
    lidar = Lidar(32, -25.0, 10.0, 720, 0.3, 30.0, 10.0)
    noise = parse_noise(["range:0.01"])
    m = VoxelMap(MapParams(radius=30.0, max_age=0.0), clear_rays=16384)
    floor_seen: set[tuple[int, int, int]] = set()
    in_box = []
    for i in range(8):
        scene = with_box if i < 3 else without
        pose = _pose(0.0, 0.1 * i, 1.0, 3.0 * i)
        cloud = finish(
            lidar.scan(scene, pose, 0.1 * i), scene, noise, np.random.default_rng(i), "world"
        )
        floor = cloud.points[cloud.surface == 0].astype(np.float64)
        floor_seen |= set(map(tuple, np.floor(floor / m.size).astype(np.int64)))
        m.integrate(cloud.points, pose, 0.1 * i, in_map_frame=True)
        c = (m.voxels()["keys"] + 0.5) * m.size
        box = (np.abs(c[:, 0] - 1.5) < 0.25) & (np.abs(c[:, 1]) < 0.25) & (c[:, 2] > 0.06)
        in_box.append(int(box.sum()))
    assert in_box[2] > 80
    assert in_box[-1] <= 0.1 * in_box[2], in_box  # ~5 % left after 5 scans, at most 10 %
    kept = set(map(tuple, m.voxels()["keys"]))
    lost = np.array([k for k in floor_seen if k not in kept]).reshape(-1, 3)
    assert len(lost) <= 0.001 * len(floor_seen)
    centre = (lost[:, :2] + 0.5) * m.size
    assert not (np.hypot(centre[:, 0], centre[:, 1]) > 4.0).any()  # far floor at grazing angles
    assert m.stats()["cleared"] > 0


def test_detection_through_the_map_finds_floor_and_table():
    from supportnode.pipeline import detect
    from supportnode.sim import Lidar, load_scene, poses_for
    from supportnode.sim.simulate import scans

    scene = load_scene("table_chairs")
    clouds = scans(scene, Lidar.preset("os128"), poses_for(scene, 4), seed=0)
    m = VoxelMap(MapParams())
    for c in clouds:
        m.integrate(c.points, c.sensor_pose, c.stamp, in_map_frame=True)
    det = detect(m.points(), objects=False, sensor_origin=clouds[-1].sensor_pose[:3, 3])
    heights = sorted(s.height for s in det.surfaces.surfaces if s.area > 0.5)
    assert any(abs(h) < 0.02 for h in heights), heights  # floor
    assert any(0.68 < h < 0.76 for h in heights), heights  # table (top 0.75, panel 0.72)


def test_bad_input_and_touched_region(rng):
    m = _no_clear()
    with pytest.raises(InputError):
        m.integrate(np.zeros((3, 2)), EYE, 0.0)
    with pytest.raises(InputError):
        m.integrate(np.zeros((3, 3)), np.eye(3), 0.0)
    pts = plane_points(rng, 0, 1, 0, 1, 0.0, 1000)
    pts[:5] = np.nan  # a driver's misses are skipped and counted
    touched = m.integrate(pts, EYE, 0.0, in_map_frame=True)
    assert m.stats()["points_invalid"] == 5
    assert len(touched.keys) == len(m)
    assert np.all(touched.lo >= -1e-12) and np.all(touched.hi <= 1.0)
    assert len(m.points(touched.keys)) == len(m.points())


@pytest.mark.parametrize("tilt_deg", [0.0, 20.0])
def test_points_in_box_holds_every_point_in_the_box(rng, tilt_deg):
    """The crop handed to regional detection: a superset of the points whose rotated x, y lie
    in the box (nothing in the box is lost), far fewer than the map, None above max_share."""
    m = _no_clear()
    m.integrate(rng.uniform(-5, 5, (40_000, 3)), EYE, 0.0)
    a = np.radians(tilt_deg)
    rot = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    lo, hi = np.array([-1.0, 0.5]), np.array([0.3, 2.0])

    def inside(p):
        q = p @ rot.T
        return p[np.all((q[:, :2] >= lo) & (q[:, :2] <= hi), axis=1)]

    want = inside(m.points())
    crop = m.points_in_box(lo, hi, rot)
    got = inside(crop)
    assert len(want) > 100
    assert len(crop) < 0.3 * len(m.points())
    key = lambda p: set(map(tuple, np.round(p, 9)))  # noqa: E731
    assert key(got) == key(want)
    assert m.points_in_box(np.array([-9.0, -9.0]), np.array([9.0, 9.0]), rot, 0.8) is None


def test_stable_points_repeat_on_a_static_scene_and_renew_where_it_changed(rng):
    """ "stable" (the default): a static scene scanned again gives detection the very same
    points, so clusters and ids do not flicker; where a new scan's rays pass through a voxel's
    kept points (a box lifted off a board: the board's voxels it stood in are hit, never seen
    through, and the rays to the board now pass where its foot was), the voxel's kept points
    are renewed from it. "recent" renews them every scan."""
    sensor = _pose(x=1.0, y=0.25, z=1.2)  # above the board, looking at the box's side

    def board():  # dense, level, z = 0.51 (inside one layer of 5 cm voxels)
        xy = rng.uniform(0.0, 0.5, (6000, 2))
        return np.c_[xy, np.full(len(xy), 0.51)]

    def box():  # its side facing the sensor, x = 0.225, rising from the board; none behind
        yz = np.c_[rng.uniform(0.0, 0.5, 3000), rng.uniform(0.51, 0.8, 3000)]
        b = board()
        return np.vstack([b[b[:, 0] > 0.225], np.c_[np.full(len(yz), 0.225), yz]])

    stable, recent = (
        _no_clear(),
        VoxelMap(MapParams(clear_free_space=False, max_age=0.0), representation="recent"),
    )
    for m in (stable, recent):
        m.integrate(board(), sensor, 0.0, in_map_frame=True)
    first = stable.points()
    for m in (stable, recent):
        m.integrate(board(), sensor, 0.1, in_map_frame=True)
    assert np.array_equal(stable.points(), first)  # the same points: nothing changed
    assert not np.array_equal(recent.points(), first)

    m = _no_clear()
    m.integrate(box(), sensor, 0.0, in_map_frame=True)
    col = np.floor(0.225 / 0.05).astype(int)
    bottom = lambda p: p[(np.floor(p[:, 0] / 0.05) == col) & (p[:, 2] < 0.55)]  # noqa: E731
    assert (bottom(m.points())[:, 2] > 0.52).any()  # the box's foot shares the board's voxels
    m.integrate(box(), sensor, 0.1, in_map_frame=True)  # the same view: nothing renewed
    assert (bottom(m.points())[:, 2] > 0.52).any()
    for stamp in (0.2, 0.3):  # the box is gone: only the board, twice
        m.integrate(board(), sensor, stamp, in_map_frame=True)
    # Renewed from the board where the box's foot stood; left: what lies on the board anyway
    # (within the 1 cm a surface's points may stray).
    assert np.abs(bottom(m.points())[:, 2] - 0.51).max() <= 0.01
    assert m.stats()["renewed"] > 0


def test_stable_points_keep_both_faces_of_a_corner_seen_from_either_side(rng):
    """A voxel where a floor meets a wall shows the floor from one viewpoint and the wall from
    another; neither view passes through the other face, so its kept points stay put (they
    flickered with the viewpoint, and so did the obstacle at the wall's foot)."""
    floor = np.c_[rng.uniform(0.0, 1.0, (20000, 2)), np.full(20000, 0.02)]
    floor = floor[floor[:, 0] < 0.52]
    wall = np.c_[np.full(8000, 0.52), rng.uniform(0.0, 1.0, 8000), rng.uniform(0.02, 0.5, 8000)]
    m = _no_clear()
    m.integrate(np.vstack([floor, wall]), _pose(x=-1.0, y=0.5, z=1.0), 0.0, in_map_frame=True)
    first = m.points()
    # The wall's foot hidden (behind a chair), from high up and from low down: only the floor;
    # then only the wall.
    for i, z in enumerate((2.0, 0.3)):
        m.integrate(floor, _pose(x=-1.0, y=0.2, z=z), 0.1 + i, in_map_frame=True)
        m.integrate(wall, _pose(x=-1.0, y=0.5, z=z), 0.2 + i, in_map_frame=True)
    assert np.array_equal(m.points(), first)
    assert m.stats()["renewed"] == 0


def test_unknown_representation_is_a_clear_error():
    with pytest.raises(InputError, match=r"representation must be one of .*stable"):
        VoxelMap(representation="newest")
