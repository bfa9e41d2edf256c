"""The node in-process: gravity, map, detection, ids, rejects (no sockets)."""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import threading
import time

import numpy as np
import pytest
from conftest import box_points, plane_points

from supportnode.client import (
    ObstacleClusters,
    Publisher,
    Subscriber,
    SupportSurfaces,
    pose_from_matrix,
)
from supportnode.errors import InputError
from supportnode.msgs import PointCloud
from supportnode.node import incremental
from supportnode.node.node import Node, quaternion_matrix
from supportnode.params import DetectParams


def _platform(rng, cx, cy, z=0.5, n=6000):
    """A 1.2 x 0.8 m horizontal board at height z, with its edges (no floor under it)."""
    return plane_points(rng, cx - 0.6, cx + 0.6, cy - 0.4, cy + 0.4, z, n)


def _cloud(points, stamp, seq=0, pose=None, **kw):
    pose = np.eye(4) if pose is None else pose
    return PointCloud.from_xyz(points, stamp, "lidar", seq=seq, pose=pose_from_matrix(pose), **kw)


def _sensor_pose(x, y, z):
    p = np.eye(4)
    p[:3, 3] = (x, y, z)
    return p


@contextlib.contextmanager
def _spinning(topics, incremental=True, **node_keys):
    """A node spinning in a thread over sockets on 127.0.0.1 (``node.*`` keys overridden):
    yields it, a publisher of scans and a subscriber of ``topics``; stops it on exit."""
    pub = Publisher("tcp://127.0.0.1:*", "scan", hwm=100)
    p = DetectParams()
    node_p = dataclasses.replace(
        p.node,
        scan_endpoint=pub.endpoint,
        pub_endpoint="tcp://127.0.0.1:*",
        map_period=0.0,
        **node_keys,
    )
    try:
        with Node(dataclasses.replace(p, node=node_p), incremental=incremental) as node:
            node.open()
            sub = Subscriber(topics, node.pub_endpoint, keep_newest=100)
            th = threading.Thread(target=node.spin, kwargs={"handle_signals": False}, daemon=True)
            th.start()
            time.sleep(0.5)  # slow joiner
            try:
                yield node, pub, sub
            finally:
                node.stop()
                th.join(5)
                sub.close()
    finally:
        pub.close()


def _summary(out):
    s = sorted((round(x.height, 6), round(x.area, 6), x.point_count) for x in out.surfaces.surfaces)
    c = sorted((tuple(np.round(x.centroid, 6)), x.point_count) for x in out.obstacles.clusters)
    return s, c


def test_surfaces_heights_and_obstacle_on_them(rng):
    pts = np.vstack([_platform(rng, 0, 0), box_points(rng, (0.1, 0.0, 0.6), (0.2, 0.2, 0.2), 3000)])
    pose = _sensor_pose(0, 0, 1.5)
    with Node() as node:
        out = node.process(_cloud(pts - pose[:3, 3], 1.0, pose=pose))
    assert [round(s.height, 2) for s in out.surfaces.surfaces] == [0.5]
    assert out.surfaces.frame_id == "map"
    assert len(out.obstacles.clusters) == 1
    c = out.obstacles.clusters[0]
    assert c.surface_id == out.surfaces.surfaces[0].id
    assert c.height == pytest.approx(0.2, abs=0.03)
    assert c.points is not None and 0 < len(c.points) <= 64


def test_stable_ids_and_safe_after_two_scans(rng):
    pose = _sensor_pose(0, 0, 1.5)
    ids, safe = [], []
    with Node() as node:
        for i in range(4):
            pts = np.vstack([_platform(rng, 0, 0), _platform(rng, 3, 0, z=0.8)])
            out = node.process(_cloud(pts - pose[:3, 3], 1.0 + 0.1 * i, seq=i + 1, pose=pose))
            ids.append(sorted(s.id for s in out.surfaces.surfaces))
            safe.append([s.safe for s in out.surfaces.surfaces])
    assert ids == [ids[0]] * 4 and len(ids[0]) == 2
    assert safe[0] == [False, False] and safe[-1] == [True, True]


@pytest.mark.parametrize(
    ("overrides", "first", "last"),
    [
        ({"node": {"safe_min_hits": 1}}, [True, True], [True, True]),
        # the 0.96 m^2 boards are too small for a 1 m^2 minimum; a 0.5 m board is higher
        ({"safe": {"min_area": 1.0}}, [False, False], [False, False]),
    ],
)
def test_safe_rule_is_configuration(rng, overrides, first, last):
    from supportnode.config import load_config

    sets = [f"{sec}.{k}={v}" for sec, kv in overrides.items() for k, v in kv.items()]
    pose = _sensor_pose(0, 0, 1.5)
    safe = []
    with Node(load_config(None, sets)) as node:
        for i in range(3):
            pts = np.vstack([_platform(rng, 0, 0), _platform(rng, 3, 0, z=0.8)])
            out = node.process(_cloud(pts - pose[:3, 3], 1.0 + 0.1 * i, seq=i + 1, pose=pose))
            safe.append([s.safe for s in out.surfaces.surfaces])
    assert safe[0] == first and safe[-1] == last


def test_incremental_equals_full_recompute(rng):
    """Two boards 4 m apart; later scans see only the first, where a box appears."""
    pose = _sensor_pose(0, 0, 1.5)
    both = np.vstack([_platform(rng, 0, 0), _platform(rng, 4, 0)])
    seq = [both]
    for k in range(4):
        one = _platform(rng, 0, 0, n=3000)
        if k >= 1:
            one = np.vstack([one, box_points(rng, (0.2, 0.1, 0.6), (0.2, 0.2, 0.2), 2000)])
        seq.append(one)
    outs = {}
    for inc in (True, False):
        with Node(incremental=inc) as node:
            outs[inc] = [
                node.process(_cloud(p - pose[:3, 3], 1.0 + 0.1 * i, pose=pose))
                for i, p in enumerate(seq)
            ]
    # The crop really ran (the box's first two scans); the last two add nothing to the map
    # (its voxels are full), and both nodes reuse their previous detection.
    assert [o.incremental for o in outs[True]] == [False, True, True, False, False]
    assert [o.reused for o in outs[True]] == [o.reused for o in outs[False]]
    assert [o.reused for o in outs[False]] == [False, False, False, True, True]
    assert not any(o.incremental for o in outs[False])
    for a, b in zip(outs[True], outs[False], strict=True):
        assert _summary(a) == _summary(b)
    assert len(outs[True][-1].obstacles.clusters) == 1


def test_unchanged_map_reuses_the_detection(rng):
    """A robot standing before a static scene: once the map's voxels hold their points, new
    scans change nothing, and the node publishes its previous detection (same surfaces, same
    ids) without running it again; a box put down changes the map and is detected."""
    pose = _sensor_pose(0, 0, 1.5)
    box = lambda: box_points(rng, (0.2, 0.1, 0.6), (0.2, 0.2, 0.2), 2000)  # noqa: E731
    with Node() as node:
        outs = [
            node.process(_cloud(_platform(rng, 0, 0) - pose[:3, 3], 1.0 + 0.1 * i, pose=pose))
            for i in range(4)
        ]
        assert [o.reused for o in outs] == [False, False, True, True]
        assert node.counters["detections_reused"] == 2
        assert all(_summary(o) == _summary(outs[1]) for o in outs[2:])
        assert [s.id for s in outs[-1].surfaces.surfaces] == [
            s.id for s in outs[1].surfaces.surfaces
        ]
        assert outs[-1].surfaces.stamp == pytest.approx(1.3)  # the scan's own stamp
        out = node.process(
            _cloud(np.vstack([_platform(rng, 0, 0), box()]) - pose[:3, 3], 1.4, pose=pose)
        )
        assert not out.reused
        assert len(out.obstacles.clusters) == 1 and not outs[-1].obstacles.clusters


def test_sensor_rising_above_a_board_publishes_its_free_space(rng):
    """Boards at 0.5 m and 1.6 m; the sensor at 1.2 m publishes only the lower one (the higher
    is an underside), and the detection leaves the higher one without free space. Once the
    map is full and the detection reused, the sensor rises to 2 m over the same scene: the
    higher board is published now, with its free space, so the reuse must not happen."""
    scene = np.vstack([_platform(rng, 0, 0), _platform(rng, 3, 0, z=1.6)])
    outs = []
    with Node() as node:
        for i, z in enumerate([1.2] * 4 + [2.0]):
            pose = _sensor_pose(0, 0, z)
            outs.append(node.process(_cloud(scene - pose[:3, 3], 1.0 + 0.1 * i, pose=pose)))
        assert [round(s.height, 2) for s in outs[3].surfaces.surfaces] == [0.5]
        got = {round(s.height, 2): s for s in outs[-1].surfaces.surfaces}
        assert sorted(got) == [0.5, 1.6]
        assert 0.9 < got[1.6].free_area <= got[1.6].area  # a 1.2 x 0.8 m board, nothing on it
        assert outs[3].reused and not outs[-1].reused


def test_regional_declines_when_surfaces_it_keeps_lack_free_space(rng):
    """A previous detection with free space below 1 m only: a regional recompute that needs
    it below 2 m cannot take the unchanged high board from it; below 1 m it can."""
    params = DetectParams()
    pts = np.vstack([_platform(rng, 0, 0), _platform(rng, 4, 0, z=1.6)])
    previous = incremental.full(pts, params, free_below=1.0)
    assert len(previous.surfaces) == 2 and len(previous.free) == 1
    box = box_points(rng, (0.2, 0.1, 0.6), (0.2, 0.2, 0.2), 2000)
    now = np.vstack([pts, box])
    lo, hi = np.array([0.1, 0.0]), np.array([0.3, 0.2])
    assert incremental.regional(now, previous, lo, hi, params, free_below=2.0) is None
    got = incremental.regional(now, previous, lo, hi, params, free_below=1.0)
    want = incremental.full(now, params, free_below=1.0)
    assert got is not None and got.region is not None
    assert sorted(round(s.height, 2) for s in got.surfaces) == [0.5, 1.6]

    def free_by_height(items):  # ids are numbered differently by the two
        height = {s.id: round(s.height, 2) for s in items.surfaces}
        out = {}
        for f in items.free:
            d = f.to_dict()
            d.pop("surface_id")
            out[height[f.surface_id]] = d
        return out

    assert free_by_height(got) == free_by_height(want) and list(free_by_height(got)) == [0.5]


def test_removed_object_leaves_the_map(rng):
    """A box on a board, then the board alone seen from the side: the rays through where the
    box stood clear it within a few scans, and its obstacle ids are reported gone. (The wall
    behind reaches the floor: every line of sight through where the box stood then ends on
    something. A part of the box that no ray crosses stays in the map until it ages out.)"""
    pose = _sensor_pose(-2.0, 0, 1.2)
    board = lambda: _platform(rng, 0, 0, n=8000)  # noqa: E731
    box = lambda: box_points(rng, (0.0, 0.0, 0.65), (0.3, 0.3, 0.3), 4000)  # noqa: E731
    wall = lambda: np.c_[  # noqa: E731 - what the rays hit once the box is gone
        np.full(6000, 2.0), rng.uniform(-1, 1, 6000), rng.uniform(0.0, 1.5, 6000)
    ]

    def at_box(clusters):  # obstacles where the box stands (it may be cut in two at its top)
        return [c for c in clusters if (np.abs(c.centroid[:2]) < 0.2).all() and c.point_count]

    with Node() as node:
        for i in range(3):
            pts = np.vstack([board(), box(), wall()])
            out = node.process(_cloud(pts - pose[:3, 3], 1.0 + 0.1 * i, pose=pose))
        box_ids = {c.id for c in at_box(out.obstacles.clusters)}
        board_id = [s.id for s in out.surfaces.surfaces if abs(s.height - 0.5) < 0.01]
        assert box_ids and any(c.surface_id in board_id for c in at_box(out.obstacles.clusters))
        gone = []
        for i in range(3, 12):
            out = node.process(
                _cloud(np.vstack([board(), wall()]) - pose[:3, 3], 1.0 + 0.1 * i, pose=pose)
            )
            gone += out.gone_ids["obstacles"]
            if not at_box(out.obstacles.clusters) and box_ids <= set(gone):
                break
        assert at_box(out.obstacles.clusters) == []
        assert box_ids <= set(gone)


def test_gravity_given_rotates_results(rng):
    """A sensor rolled by 20 deg: once gravity.min_agreeing (3) scans give the same gravity
    vector, it is the map's up and the board comes out level; one scan alone never sets it."""
    roll = np.radians(20)
    r = np.array([[1, 0, 0], [0, np.cos(roll), -np.sin(roll)], [0, np.sin(roll), np.cos(roll)]])
    pts = _platform(rng, 0, 0, z=-1.0) @ r.T  # seen by a rolled sensor at the origin
    g = r @ np.array([0.0, 0.0, -9.81])
    with Node() as node:
        for i in range(3):
            out = node.process(
                PointCloud.from_xyz(
                    pts, 1.0 + 0.1 * i, "lidar", gravity=g, pose=(np.zeros(3), [0, 0, 0, 1])
                )
            )
            d = node.diagnostics()
            if i < 2:  # 20 deg from the assumed +z: waits for agreeing scans
                assert d.gauges["gravity_source"] == 0.0 and d.gauges["gravity_tilt_deg"] == 0
    assert len(out.surfaces.surfaces) == 1
    assert out.surfaces.surfaces[0].height == pytest.approx(-1.0, abs=0.02)
    assert d.gauges["gravity_tilt_deg"] == pytest.approx(20.0, abs=0.01)
    assert d.gauges["gravity_source"] == 1.0
    assert d.counters["gravity_outliers"] == 2  # the two that came before agreement


def test_reset_keeps_the_map_frames_up_and_forgets_the_map(rng):
    """The up set by agreeing scans' gravity belongs to the map frame: a reset (a source that
    restarted) forgets the map and ids, not the up."""
    g = [0.0, 0.2, -9.8]  # 1.2 deg off -z
    with Node() as node:
        for i in range(3):
            node.process(
                _cloud(
                    _platform(rng, 0, 0) - [0, 0, 1.5],
                    1.0 + 0.1 * i,
                    gravity=g,
                    pose=_sensor_pose(0, 0, 1.5),
                )
            )
        up = node.diagnostics().gauges["gravity_tilt_deg"]
        node.reset()
        d = node.diagnostics()
    assert up == pytest.approx(1.17, abs=0.01)
    assert d.gauges["gravity_source"] == 1.0 and d.gauges["gravity_tilt_deg"] == up
    assert d.gauges["map_voxels"] == 0


def test_gravity_estimated_without_imu_levels_results(rng):
    """No gravity in the scans, gravity.enabled: the node fits up from the normals of a floor
    and a table seen by a sensor rolled 20 deg and pitched 10 deg, publishes the correction,
    and the surfaces come out level at their heights below the sensor."""
    import dataclasses

    roll, pitch = np.radians(20), np.radians(10)
    rx = np.array([[1, 0, 0], [0, np.cos(roll), -np.sin(roll)], [0, np.sin(roll), np.cos(roll)]])
    ry = np.array(
        [[np.cos(pitch), 0, np.sin(pitch)], [0, 1, 0], [-np.sin(pitch), 0, np.cos(pitch)]]
    )
    r = ry @ rx
    world = np.vstack(
        [plane_points(rng, -3, 3, -3, 3, -1.5, 40000), _platform(rng, 0.5, 0.5, z=-0.75)]
    )
    p = DetectParams()
    p = dataclasses.replace(p, gravity=dataclasses.replace(p.gravity, enabled=True))
    with Node(p) as node:
        for i in range(3):
            cloud = PointCloud.from_xyz(world @ r.T, 1.0 + 0.1 * i, "lidar", seq=i + 1)
            out = node.process(cloud)
        d = node.diagnostics()
    assert d.gauges["gravity_source"] == 2.0  # estimated
    tilt = np.degrees(np.arccos(np.clip((r @ [0, 0, 1])[2], -1, 1)))
    assert d.gauges["gravity_tilt_deg"] == pytest.approx(tilt, abs=0.5)
    heights = sorted(round(s.height, 2) for s in out.surfaces.surfaces)
    assert heights == [-1.5, -0.75]
    assert all(s.normal[2] > np.cos(np.radians(1.0)) for s in out.surfaces.surfaces)


def test_quaternion_matrix_matches_pose_from_matrix():
    a = np.radians(33)
    r = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = r
    assert np.allclose(quaternion_matrix(pose_from_matrix(m).rotation), r)


def test_detection_rate_skips_scans_but_keeps_the_map(rng):
    params = DetectParams()
    import dataclasses

    params = dataclasses.replace(params, node=dataclasses.replace(params.node, detection_rate=2))
    pose = _sensor_pose(0, 0, 1.5)
    with Node(params) as node:
        outs = [
            node.process(_cloud(_platform(rng, 0, 0) - pose[:3, 3], 1.0 + 0.1 * i, pose=pose))
            for i in range(11)
        ]
    assert [o.surfaces is not None for o in outs] == [i % 5 == 0 for i in range(11)]


def test_time_jump_resets_map_and_ids(rng):
    pose = _sensor_pose(0, 0, 1.5)
    with Node() as node:
        node.process(_cloud(_platform(rng, 0, 0) - pose[:3, 3], 10.0, pose=pose))
        out = node.process(_cloud(_platform(rng, 3, 0) - pose[:3, 3], 0.0, pose=pose))
        assert node.counters["time_jumps"] == 1
    assert len(out.surfaces.surfaces) == 1
    assert out.surfaces.surfaces[0].id == 0  # ids start over with the new timeline


def test_handle_rejects_and_goes_on(rng):
    pose = _sensor_pose(0, 0, 1.5)
    good = _cloud(_platform(rng, 0, 0) - pose[:3, 3], 1.0, pose=pose).encode("scan")
    frames = [bytes(f) for f in good]
    bad_version = list(frames)
    bad_version[1] = bad_version[1].replace(b"\xa7version\x01", b"\xa7version\x07")
    nan = np.full((100, 3), np.nan)
    cases = {
        "malformed": [b"scan", b"\xc1garbage"],
        "version": bad_version,
        "unusable": [bytes(f) for f in PointCloud.from_xyz(nan, 1.0, "x").encode("scan")],
        "truncated": [b"scan"] + frames[1:-1],
    }
    with Node() as node:
        for frames_ in cases.values():
            assert node.handle(frames_) is None
        assert node.handle(frames) is not None
        for seed in range(200):  # random byte flips in the header
            r = np.random.default_rng(seed)
            f = list(frames)
            h = bytearray(f[1])
            for _ in range(3):
                h[r.integers(len(h))] = r.integers(256)
            f[1] = bytes(h)
            node.handle(f)
        # A flip may have left an admitted stamp after the good scan's: its timeline is then
        # confirmed by a second scan continuing it.
        again = [_cloud(_platform(rng, 0, 0) - pose[:3, 3], t, pose=pose) for t in (2.0, 2.1)]
        node.handle(again[0].encode("scan"))
        assert node.handle(again[1].encode("scan")) is not None
        assert node.rejects["version"] == 1
        assert node.rejects["all_nonfinite"] == 1
        assert node.rejects["malformed"] >= 2
        assert node.counters["scans_rejected"] == sum(node.rejects.values())
    with pytest.raises(InputError):
        Node().process(PointCloud.from_xyz(np.zeros((0, 3)), 1.0, "x"))


def test_too_many_points_rejected(rng):
    import dataclasses

    p = DetectParams()
    p = dataclasses.replace(p, node=dataclasses.replace(p.node, max_points=1000))
    with Node(p) as node:
        assert node.handle(_cloud(_platform(rng, 0, 0, n=2000), 1.0).encode("scan")) is None
        assert node.rejects == {"too_many_points": 1}


def test_slow_detection_over_sockets(rng, monkeypatch):
    """Scans at a rate detection cannot follow: every scan still enters the map and detection
    skips to the newest (counted); results keep coming, for the newest scans."""
    from supportnode.node import incremental

    full = incremental.begin_full

    def slow_full(*a, **kw):
        time.sleep(0.25)
        return full(*a, **kw)

    monkeypatch.setattr(incremental, "begin_full", slow_full)
    pose = _sensor_pose(0, 0, 1.5)
    pts = _platform(rng, 0, 0) - pose[:3, 3]
    with _spinning("surfaces", False) as (node, pub, sub):
        n = 12
        for i in range(n):
            pub.publish(_cloud(pts, 1.0 + 0.1 * i, seq=i + 1, pose=pose))
            time.sleep(0.05)
        got = []
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            msg = sub.recv(0.5)
            if isinstance(msg, SupportSurfaces):
                got.append(msg)
                if msg.stamp == pytest.approx(1.0 + 0.1 * (n - 1)):
                    break
        d = node.diagnostics()
    c = d.counters
    assert got and got[-1].stamp == pytest.approx(1.0 + 0.1 * (n - 1)), "the newest scan"
    assert [round(s.height, 2) for s in got[-1].surfaces] == [0.5]
    assert c["detections"] < n
    assert c["scans_processed"] == n and c["scans_dropped"] == 0, c
    assert c["detections_skipped"] >= 1
    assert _accounted(c) == n, c


def test_detector_behind_publishes_newer_surfaces_before_older_obstacles(rng, monkeypatch):
    """Surfaces slower than the scan period: once a newer scan waits, the detector publishes
    its surfaces before the older scan's obstacles, which are skipped (counted), never two
    in a row; every detected scan has its surfaces published."""
    _slow_stages(monkeypatch, merge_s=0.0, detect_s=0.15)
    pose = _sensor_pose(0, 0, 1.5)
    pts = _platform(rng, 0, 0) - pose[:3, 3]
    n = 10
    with _spinning(["surfaces", "obstacles"], False) as (node, pub, sub):
        for i in range(n):
            pub.publish(_cloud(pts + 0.001 * i, 1.0 + 0.1 * i, seq=i + 1, pose=pose))
            time.sleep(0.1)
        got: list = []
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            msg = sub.recv(0.5)
            if msg is None and _accounted(node.counters) == n:
                break  # every scan detected, skipped or yielded, and its messages received
            if isinstance(msg, SupportSurfaces | ObstacleClusters):
                got.append(msg)
        c = node.counters
    assert c["obstacles_skipped"] >= 2, c
    assert _accounted(c) == n, c
    seqs = {
        k: [m.seq for m in got if isinstance(m, k)] for k in (SupportSurfaces, ObstacleClusters)
    }
    surfaces, obstacles = seqs[SupportSurfaces], seqs[ObstacleClusters]
    assert len(surfaces) == c["detections"] + c["obstacles_skipped"]
    assert set(obstacles) < set(surfaces)
    missing = [s not in obstacles for s in surfaces]
    assert sum(missing) == c["obstacles_skipped"]
    assert not any(a and b for a, b in itertools.pairwise(missing)), seqs


def _accounted(c: dict[str, int]) -> int:
    """Scans the detector has finished with: detected, skipped, or their obstacles yielded."""
    return c["detections"] + c["detections_skipped"] + c["obstacles_skipped"]


def _slow_stages(monkeypatch, merge_s: float, detect_s: float) -> None:
    """Every merge into the map and every full detection take this much longer (s)."""
    from supportnode.map import VoxelMap
    from supportnode.node import incremental

    merge, full = VoxelMap.merge, incremental.begin_full

    def slow_merge(self, *a, **kw):
        time.sleep(merge_s)
        return merge(self, *a, **kw)

    def slow_full(*a, **kw):
        time.sleep(detect_s)
        return full(*a, **kw)

    monkeypatch.setattr(VoxelMap, "merge", slow_merge)
    monkeypatch.setattr(incremental, "begin_full", slow_full)


def test_scan_merged_after_detection_ended_is_detected(rng, monkeypatch):
    """A scan that arrives while detection runs, but whose merge ends after it, has not waited
    for the detector: it is detected at once, not held back in the hope of a fresher one."""
    _slow_stages(monkeypatch, merge_s=0.15, detect_s=0.4)
    pose = _sensor_pose(0, 0, 1.5)
    pts = _platform(rng, 0, 0) - pose[:3, 3]
    n = 6
    with _spinning("surfaces", False) as (node, pub, _):
        # Every 0.5 s: each arrives 0.35 s after the previous one's merge ended, during its
        # detection (0.4 s), and is merged 0.1 s after that detection ended.
        for i in range(n):
            pub.publish(_cloud(pts + 0.001 * i, 1.0 + 0.1 * i, seq=i + 1, pose=pose))
            time.sleep(0.5)
        deadline = time.monotonic() + 10
        while _accounted(node.counters) < n and time.monotonic() < deadline:
            time.sleep(0.05)
        c = dict(node.counters)
        total = node.latency.stats()["total"].p50  # receive to results
    assert c["scans_processed"] == n and c["detections_skipped"] == 0, c
    # Each scan's surfaces detected; obstacles of one whose successor was merging at the end
    # of its surfaces may have yielded to that successor's surfaces.
    assert c["detections"] + c["obstacles_skipped"] == n
    # Merge 0.15 s + detection 0.4 s, and no wait for a fresher scan.
    assert total < 0.75, total


def test_decoder_bug_is_a_reject_not_the_end_of_the_node(rng, monkeypatch):
    """An unexpected error while decoding a message off the socket (a bug, not a malformed
    message) is logged, counted as an internal_error reject, and the node goes on with the
    next scan."""
    from supportnode.node import intake as node_module

    decode = node_module.decode_any

    def flaky(frames, limits):
        msg = decode(frames, limits)
        if msg.seq == 2:
            raise RuntimeError("decoder bug")
        return msg

    monkeypatch.setattr(node_module, "decode_any", flaky)
    pose = _sensor_pose(0, 0, 1.5)
    pts = _platform(rng, 0, 0) - pose[:3, 3]
    with _spinning("surfaces", False) as (node, pub, sub):
        for i in range(3):
            pub.publish(_cloud(pts, 1.0 + 0.1 * i, seq=i + 1, pose=pose))
            time.sleep(0.3)
        got = []
        deadline = time.monotonic() + 10
        while len(got) < 2 and time.monotonic() < deadline:
            if (msg := sub.recv(0.1)) is not None:
                got.append(msg.seq)
        c, rejects = dict(node.counters), dict(node.rejects)
    assert rejects == {"internal_error": 1} and c["scans_rejected"] == 1
    assert c["scans_processed"] == 2 and len(got) == 2


def test_real_kinect_sequence_keeps_its_points_and_ids(real_scans):
    """Three real Kinect-class frames (0.25 s apart, a laptop and a box on a table), fed in a
    loop with gravity estimated from normals: once the map has seen them, a scan renews the
    kept points of few voxels (real noise is no reason to), and the obstacles keep their ids."""
    from dataclasses import replace

    from supportnode.io.clouds import read_cloud

    frames = [read_cloud(f).points for f in sorted(real_scans.glob("grabber_frame_*.pcd"))]
    assert len(frames) == 3
    p = DetectParams()
    with Node(replace(p, gravity=replace(p.gravity, enabled=True))) as node:
        outs, renewed = [], []
        for i in range(9):
            before = node.map.stats()["renewed"]
            outs.append(node.process(PointCloud.from_xyz(frames[i % 3], 1.0 + 0.25 * i, "cam")))
            renewed.append(node.map.stats()["renewed"] - before)
        voxels = node.map.stats()["voxels"]
    assert max(renewed[3:]) <= 0.02 * voxels  # 4-6 of ~1,230; 11-26 % by the plane test alone
    assert sum(len(o.new_ids["obstacles"]) for o in outs[3:]) <= 1
    assert [len(o.surfaces.surfaces) for o in outs[3:]] == [1] * 6


def test_surfaces_then_obstacles_over_sockets(rng):
    """Each detection's surfaces (with free space) go out as soon as they are known, before
    its obstacles (same seq), which refer to them. Every detection sends both."""
    pose = _sensor_pose(0, 0, 1.5)
    box = box_points(rng, (0.1, 0.0, 0.6), (0.2, 0.2, 0.2), 3000)
    pts = np.vstack([_platform(rng, 0, 0), box]) - pose[:3, 3]
    order = []
    with _spinning(["surfaces", "obstacles"], False) as (node, pub, sub):
        for i in range(3):
            pub.publish(_cloud(pts, 1.0 + 0.1 * i, seq=i + 1, pose=pose))
            deadline = time.monotonic() + 10
            while len(order) < 2 * (i + 1) and time.monotonic() < deadline:
                msg = sub.recv(0.2)
                if isinstance(msg, SupportSurfaces | ObstacleClusters):
                    order.append((msg.seq, type(msg).__name__, msg))
        d = node.diagnostics()
    kinds = ("SupportSurfaces", "ObstacleClusters")
    assert [(s, k) for s, k, _ in order] == [(s, k) for s in (1, 2, 3) for k in kinds]
    surfaces = [m for _, k, m in order if k == "SupportSurfaces"]
    obstacles = [m for _, k, m in order if k == "ObstacleClusters"]
    assert [round(s.height, 2) for s in surfaces[-1].surfaces] == [0.5]
    assert obstacles[-1].clusters[0].surface_id == surfaces[-1].surfaces[0].id
    assert surfaces[-1].surfaces[0].free_area < surfaces[-1].surfaces[0].area  # the box
    assert 0 < d.latencies["receive_to_surfaces"].p50 <= d.latencies["receive_to_publish"].p99


def test_removed_object_leaves_the_results_over_sockets(rng):
    """`spin`: a box taken away leaves the published obstacles within a few scans, and the
    map counts what it cleared."""
    pose = _sensor_pose(-2.0, 0, 1.2)
    board = lambda: _platform(rng, 0, 0, n=8000)  # noqa: E731
    box = lambda: box_points(rng, (0.0, 0.0, 0.65), (0.3, 0.3, 0.3), 4000)  # noqa: E731
    wall = lambda: np.c_[  # noqa: E731
        np.full(6000, 2.0), rng.uniform(-1, 1, 6000), rng.uniform(0.0, 1.5, 6000)
    ]
    at_box = lambda m: [c for c in m.clusters if (np.abs(c.centroid[:2]) < 0.2).all()]  # noqa: E731
    seen = []
    with _spinning("obstacles", False) as (node, pub, sub):
        for i in range(14):
            parts = [board(), box(), wall()] if i < 3 else [board(), wall()]
            stamp = 1.0 + 0.1 * i
            pub.publish(_cloud(np.vstack(parts) - pose[:3, 3], stamp, seq=i + 1, pose=pose))
            deadline = time.monotonic() + 20
            while True:
                msg = sub.recv(0.2)
                if isinstance(msg, ObstacleClusters) and msg.stamp == pytest.approx(stamp):
                    seen.append(len(at_box(msg)))
                    break
                assert time.monotonic() < deadline, f"no obstacles for scan {i}"
            if i >= 3 and seen[-1] == 0:
                break
        d = node.diagnostics()
    assert seen[2] >= 1 and seen[-1] == 0, seen
    c = d.counters
    assert c["map_cleared"] > 0 and c["detections"] == len(seen), c


def _removed_box_clouds(rng, pose, n=10, wall_only=False):
    """Scans of a box on a board before a wall (the box gone from the fourth scan on), in the
    sensor frame of ``pose`` (as in test_removed_object_leaves_the_map). wall_only: a floor
    patch 4 m to the side in the first scans, and once the box is gone only a band of the wall
    whose rays from (-2, 0, 1.2) pass through where the box stood and above the board (the
    scans' box then holds neither)."""
    clouds = []
    for i in range(n):
        z = (0.0, 1.5)
        parts = [_platform(rng, 0, 0, n=8000)]
        if i < 3:
            parts.append(box_points(rng, (0.0, 0.0, 0.65), (0.3, 0.3, 0.3), 4000))
            if wall_only:
                parts.append(plane_points(rng, -2, 2, 4, 6, 0.0, 20000))
        elif wall_only:
            parts, z = [], (0.15, 0.4)
        parts.append(np.c_[np.full(6000, 2.0), rng.uniform(-1, 1, 6000), rng.uniform(*z, 6000)])
        clouds.append(_cloud(np.vstack(parts) - pose[:3, 3], 1.0 + 0.1 * i, seq=i + 1, pose=pose))
    return clouds


def test_cleared_region_is_detected_again(rng):
    """What a scan's clearing removed joins the region the next detection recomputes, and
    changes the map's version: a node detecting regionally (or reusing its last detection on
    an unchanged map) publishes what a full recompute does, and the box leaves the results,
    also where the scans that follow do not reach (only a band of the wall behind it)."""
    pose = _sensor_pose(-2.0, 0, 1.2)
    clouds = _removed_box_clouds(rng, pose, 10, wall_only=True)
    outs = {}
    for inc in (True, False):
        with Node(incremental=inc) as node:
            outs[inc] = [node.process(cloud) for cloud in clouds]
            assert node.map.stats()["cleared"] > 0
    assert any(o.incremental for o in outs[True])
    for a, b in zip(outs[True], outs[False], strict=True):
        assert _summary(a) == _summary(b)

    def at_box(out):
        return [c for c in out.obstacles.clusters if (np.abs(c.centroid[:2]) < 0.2).all()]

    def box_points_seen(out):
        return sum(c.point_count for c in at_box(out))

    # Where rays from the sensor cross (its top and the side facing the sensor) it goes.
    assert box_points_seen(outs[True][-1]) < 0.7 * box_points_seen(outs[True][2])


def test_regional_objects_it_cannot_vouch_for_come_from_a_full_recompute(rng, monkeypatch):
    """Surfaces go out after the first phase; when the objects of a regional detection then
    cannot be vouched for (here: every new cluster refused), the objects are a full
    recompute's, on the surfaces already out (same surfaces, their ids kept)."""
    params = DetectParams()
    pts = np.vstack([_platform(rng, 0, 0), _platform(rng, 4, 0)])
    previous = incremental.full(pts, params)
    box = box_points(rng, (0.2, 0.1, 0.6), (0.2, 0.2, 0.2), 2000)
    now = np.vstack([pts, box])
    lo, hi = np.array([0.1, 0.0]), np.array([0.3, 0.2])
    kept = incremental._kept
    monkeypatch.setattr(
        incremental,
        "_kept",
        lambda items, *a: None if items and hasattr(items[0], "surface_id") else kept(items, *a),
    )
    phase = incremental.begin_regional(now, previous, lo, hi, params)
    assert phase is not None
    got = phase.finish()
    want = incremental.full(now, params)
    assert got.region is None  # not a regional result
    assert got.surfaces is phase.surfaces and got.free is phase.free
    height = {s.id: round(s.height, 2) for s in got.surfaces}
    want_height = {s.id: round(s.height, 2) for s in want.surfaces}
    assert len(got.clusters) == len(want.clusters) >= 1
    for g, w in zip(got.clusters, want.clusters, strict=True):
        assert g.point_count == w.point_count
        assert height.get(g.surface_id) == want_height.get(w.surface_id)
