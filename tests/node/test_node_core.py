"""NodeCore and its threads: published results equal `Node.process`, the latest-job mailbox,
resets across the two sides, warm-up before subscribing, removed configuration keys."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest
from conftest import box_points, plane_points, spinning_node

from supportnode.client import (
    ObstacleClusters,
    Publisher,
    Subscriber,
    SupportSurfaces,
    pose_from_matrix,
)
from supportnode.config import REMOVED_KEYS, load_config
from supportnode.errors import ConfigError
from supportnode.msgs import PointCloud
from supportnode.node.core import Job, NodeCore
from supportnode.node.mailbox import Mailbox
from supportnode.node.node import Node


def _pose(x: float, y: float, z: float) -> np.ndarray:
    p = np.eye(4)
    p[:3, 3] = (x, y, z)
    return p


def _scans(rng, n: int) -> list[PointCloud]:
    """A board with a box on it seen by a sensor moving along x (noisy: 5 mm), the box taken
    away half-way: the map grows, clears and changes."""
    out = []
    for i in range(n):
        pose = _pose(-0.3 + 0.05 * i, 0.0, 1.5)
        parts = [plane_points(rng, -0.6, 0.6, -0.4, 0.4, 0.5, 4000)]
        if i < n // 2:
            parts.append(box_points(rng, (0.1, 0.0, 0.6), (0.2, 0.2, 0.2), 2000))
        parts.append(plane_points(rng, -2, 2, -2, 2, 0.0, 6000))
        pts = np.vstack(parts) + rng.normal(0, 0.005, (sum(len(p) for p in parts), 3))
        out.append(
            PointCloud.from_xyz(
                pts - pose[:3, 3], 1.0 + 0.1 * i, "lidar", seq=i + 1, pose=pose_from_matrix(pose)
            )
        )
    return out


def _summary(surfaces: SupportSurfaces, obstacles: ObstacleClusters):
    s = [
        (x.id, round(x.height, 6), round(x.area, 6), x.point_count, x.safe)
        for x in surfaces.surfaces
    ]
    c = [(x.id, tuple(np.round(x.centroid, 6)), x.point_count) for x in obstacles.clusters]
    return surfaces.seq, s, c


def test_a_jobs_points_are_the_map_before_its_scans_clearing(rng):
    """`ingest` hands over the map's points with the scan merged; `settle` then clears along
    its rays: the job keeps what it took, and the next job's region covers what went."""
    core = NodeCore()
    gone = np.zeros((0, 2))  # x, y of the voxel centres the last clearing removed
    for cloud in _scans(rng, 10):
        job = core.ingest(cloud)
        assert job is not None
        if len(gone):  # the previous scan's clearing: inside this job's region
            lo, hi = job.region
            assert (lo <= gone.min(axis=0)).all() and (gone.max(axis=0) <= hi).all()
        before = core.map.points().copy()
        assert np.array_equal(job.points, before)
        keys = {tuple(k) for k in core.map.voxels()["keys"]}
        core.settle()
        left = {tuple(k) for k in core.map.voxels()["keys"]}
        assert np.array_equal(job.points, before)  # the job's points are its own
        gone = (np.array(sorted(keys - left)).reshape(-1, 3)[:, :2] + 0.5) * core.map.size
        if len(gone):
            assert len(core.map.points()) < len(before)
    assert core.map.stats()["cleared"] > 0


def test_published_results_equal_node_process(rng):
    """Over sockets, one scan at a time (none skipped), the node publishes for each scan what
    `Node.process` returns on the same scans: ids, heights, areas, obstacles, seq."""
    clouds = _scans(rng, 8)
    with Node() as ref:
        want = [_summary(o.surfaces, o.obstacles) for o in map(ref.process, clouds)]
    got = []
    with Publisher("tcp://127.0.0.1:*", "scan", hwm=100) as pub:
        with spinning_node(scan_endpoint=pub.endpoint, pub_endpoint="tcp://127.0.0.1:*") as (
            node,
            _,
        ):
            sub = Subscriber(["surfaces", "obstacles"], node.pub_endpoint, keep_newest=100)
            time.sleep(0.5)  # slow joiner
            try:
                for cloud in clouds:
                    pub.publish(cloud)
                    pair: dict[str, object] = {}
                    deadline = time.monotonic() + 20
                    while len(pair) < 2:
                        assert time.monotonic() < deadline, f"no results for scan {cloud.seq}"
                        msg = sub.recv(0.1)
                        if isinstance(msg, SupportSurfaces | ObstacleClusters):
                            assert msg.stamp == pytest.approx(cloud.stamp)
                            pair[type(msg).__name__] = msg
                    got.append(_summary(pair["SupportSurfaces"], pair["ObstacleClusters"]))
                c = node.counters
            finally:
                sub.close()
    assert c["detections_skipped"] == 0 and c["detections"] == len(clouds)
    assert got == want


def _job(stamp: float, lo, hi) -> Job:
    return Job(
        points=np.zeros((0, 3)),
        rotation=np.eye(3),
        sensor_z=1.0,
        stamp=stamp,
        frame="map",
        generation=1,
        source=(1, 0),
        region=(np.asarray(lo, float), np.asarray(hi, float)),
    )


def test_mailbox_keeps_the_latest_job_and_the_union_of_their_regions():
    box = Mailbox()
    assert box.take(0.0) is None
    box.put(_job(1.0, [0, 0], [1, 1]))
    box.put(_job(2.0, [2, -1], [3, 0.5]))
    job = box.take(0.0)
    assert job is not None and job.stamp == 2.0 and box.skipped == 1
    assert job.region[0].tolist() == [0, -1] and job.region[1].tolist() == [3, 1]
    assert box.take(0.0) is None  # taken: the mailbox is empty
    box.put(_job(3.0, [5, 5], [6, 6]))
    assert box.take(0.0).region[0].tolist() == [5, 5]  # no union with a job already taken


def test_mailbox_close_wakes_a_waiting_detector():
    box = Mailbox()
    got = []
    th = threading.Thread(target=lambda: got.append(box.take(10.0)))
    th.start()
    time.sleep(0.1)
    t = time.monotonic()
    box.close()
    th.join(5)
    assert got == [None] and time.monotonic() - t < 1.0


def test_detector_behind_yields_a_jobs_objects_to_the_newer_job():
    """A job whose surfaces are out is folded into a newer one waiting (its region joins,
    counted); with none waiting and no merge under way the detector goes on at once; a merge
    under way is waited for, and a merge that ends without a job lets it go on."""
    box = Mailbox()
    t = time.monotonic()
    assert not box.yield_to_newer(_job(1.0, [0, 0], [1, 1]), 5.0)
    assert time.monotonic() - t < 0.5 and box.obstacles_skipped == 0
    box.put(_job(2.0, [2, -1], [3, 0.5]))
    assert box.yield_to_newer(_job(1.0, [0, 0], [1, 1]), 5.0) and box.obstacles_skipped == 1
    job = box.take(0.0)
    assert job.stamp == 2.0 and box.skipped == 0
    assert job.region[0].tolist() == [0, -1] and job.region[1].tolist() == [3, 1]

    def merge(then_put: bool) -> None:
        time.sleep(0.1)
        if then_put:
            box.put(_job(3.0, [5, 5], [6, 6]))
        box.merging(False)

    for then_put in (True, False):
        box.merging(True)
        th = threading.Thread(target=merge, args=(then_put,))
        th.start()
        t = time.monotonic()
        assert box.yield_to_newer(_job(2.5, [4, 4], [4.5, 4.5]), 5.0) == then_put
        assert 0.05 < time.monotonic() - t < 2.0  # waited for the merge, not the timeout
        th.join(5)
        if then_put:
            assert box.take(0.0).region[0].tolist() == [4, 4]
    assert box.take(0.0) is None and box.obstacles_skipped == 2


def test_a_reset_reaches_the_detecting_side_through_the_job(rng):
    """The receiving side resets the map (a source restarted); the detecting side forgets its
    ids when it sees the first job of the new map, also when a job of the old map comes in
    between (it is detected on its own points, with the old ids)."""
    clouds = _scans(rng, 3)
    core = NodeCore()
    first = core.detect(core.ingest(clouds[0]))
    old = core.ingest(clouds[1])
    back = dataclasses.replace(clouds[2], stamp=0.1)  # before the previous: a restart
    new = core.ingest(back)
    assert core.ingest_counters["time_jumps"] == 1 and new.generation == old.generation + 1
    again = core.detect(old)
    assert [s.id for s in again.surfaces.surfaces] == [s.id for s in first.surfaces.surfaces]
    fresh = core.detect(new)
    assert fresh.surfaces.seq == 1  # a new map: messages and ids start over
    assert set(fresh.new_ids["surfaces"]) == {s.id for s in fresh.surfaces.surfaces}


def test_kernels_are_warmed_before_the_node_subscribes(monkeypatch):
    from supportnode.kernels import runtime

    seen = []
    warm = runtime.warm

    def recording(*a, **kw):
        seen.append(node._sub is None)
        return warm(*a, **kw)

    monkeypatch.setattr(runtime, "warm", recording)
    node = Node(
        dataclasses.replace(
            Node().params,
            node=dataclasses.replace(
                Node().params.node,
                scan_endpoint="tcp://127.0.0.1:*",
                scan_bind=True,
                pub_endpoint="tcp://127.0.0.1:*",
            ),
        )
    )
    # on_ready (`supportnode run`: the collector's freeze) once kernels and sockets are ready,
    # before the node counts as ready and takes a scan
    ready_calls = []

    def on_ready():
        ready_calls.append((len(seen), node._sub is not None, node.diagnostics().gauges["ready"]))

    with node:
        assert node.diagnostics().gauges["ready"] == 0.0
        kw = {"handle_signals": False, "on_ready": on_ready}
        th = threading.Thread(target=node.spin, kwargs=kw, daemon=True)
        th.start()
        deadline = time.monotonic() + 30
        while node.diagnostics().gauges["ready"] != 1.0:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        node.stop()
        th.join(10)
        assert node.diagnostics().gauges["ready"] == 0.0
    assert seen and all(seen)  # warmed (before and after the rehearsal), then subscribed
    assert ready_calls == [(len(seen), True, 0.0)]


def test_the_run_command_freezes_the_collector_once_the_node_is_ready(monkeypatch):
    """`supportnode run` leaves the ~1.4e5 objects its kernels made out of the collector's
    passes: a full pass over them took 20-50 ms, in the middle of a scan (issue 20's p99)."""
    from supportnode.cli import _process, main

    hooks = []
    monkeypatch.setattr(
        Node, "spin", lambda self, duration=None, on_ready=None: hooks.append(on_ready)
    )
    assert main(["run", "--duration", "0.1", "--set", "node.scan_endpoint=tcp://127.0.0.1:1"]) == 0
    assert hooks == [_process.freeze]


@pytest.mark.parametrize("key", sorted(k for k in REMOVED_KEYS if k.startswith("node.")))
def test_removed_keys_say_what_replaces_them(tmp_path, key):
    section, name = key.split(".")
    with pytest.raises(ConfigError, match=rf"--set {key}=1: key '{key}' was removed in 0\.2"):
        load_config(None, [f"{key}=1"])
    path = tmp_path / "old.yaml"
    path.write_text(f"{section}:\n  name: x\n  {name}: true\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert str(err.value).startswith(f"{path}:3: key '{key}' was removed in 0.2: ")
    assert "nothing to set" in str(err.value) or "use" in str(err.value)
