"""Detection in a worker process: the same answer as in-process, errors reported, a dead worker
noticed, and a node that loses its worker goes on detecting."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from conftest import box_points, plane_points

from supportnode.client import Publisher, Subscriber, SupportSurfaces, pose_from_matrix
from supportnode.msgs import PointCloud
from supportnode.node import incremental
from supportnode.node.node import Node
from supportnode.node.worker import DetectionWorker, WorkerError
from supportnode.params import DetectParams


def _scene(rng) -> np.ndarray:
    """A floor with a table and a box on it: (N, 3) float64, metres."""
    floor = plane_points(rng, -2, 2, -2, 2, 0.0, 20000)
    table = plane_points(rng, -0.6, 0.6, -0.4, 0.4, 0.75, 6000)
    box = box_points(rng, (0.0, 0.0, 0.75 + 0.1), (0.2, 0.2, 0.2), 3000)
    return np.concatenate([floor, table, box]).astype(np.float64)


def _started(params=None) -> DetectionWorker:
    w = DetectionWorker.start(params or DetectParams())
    deadline = time.monotonic() + 60
    while not w.ready():
        assert time.monotonic() < deadline, "worker did not start"
        time.sleep(0.02)
    return w


def _same(a: incremental.Items, b: incremental.Items) -> None:
    for name in ("surfaces", "clusters", "free"):
        assert [x.to_dict() for x in getattr(a, name)] == [x.to_dict() for x in getattr(b, name)]
    assert len(a.cluster_points) == len(b.cluster_points)
    for p, q in zip(a.cluster_points, b.cluster_points, strict=True):
        np.testing.assert_array_equal(p, q)


def test_worker_detects_what_the_node_thread_detects(rng):
    pts = _scene(rng)
    w = _started()
    try:
        got = [w.detect(pts), w.detect(pts)]  # the second one from the worker's memo
    finally:
        w.close()
    want = incremental.full(pts, DetectParams())
    assert sorted(round(s.height, 2) for s in want.surfaces) == [0.0, 0.75]
    assert len(want.clusters) >= 1
    for items in got:
        _same(items, want)
        assert items.timings["worker"] > 0


def test_error_in_detection_is_reported_and_the_worker_goes_on(rng):
    w = _started()
    try:
        with pytest.raises(RuntimeError, match="in the detection worker"):
            w.detect(np.zeros((100, 2)))  # not (N, 3): detection itself fails
        pts = _scene(rng)
        _same(w.detect(pts), incremental.full(pts, DetectParams()))
    finally:
        w.close()


def test_dead_worker_raises_worker_error_and_close_is_idempotent(rng):
    w = _started()
    os.kill(w.pid, signal.SIGKILL)
    with pytest.raises(WorkerError, match="died"):
        w.detect(_scene(rng))
    w.close()
    w.close()
    with pytest.raises(WorkerError, match="not ready"):
        w.detect(_scene(rng))


def test_close_ends_the_worker_process():
    w = _started()
    pid = w.pid
    w.close()
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # reaped, not a zombie


def test_stop_while_detecting_returns_within_the_poll(rng):
    big = np.concatenate([_scene(rng) + (5.0 * i, 0.0, 0.0) for i in range(20)])
    w = _started()
    stop = threading.Event()
    threading.Timer(0.1, stop.set).start()
    t = time.monotonic()
    with pytest.raises(WorkerError, match="stopped"):
        w.detect(big, stop)
    assert time.monotonic() - t < 2.0  # detection of ~600k points takes longer
    w.close()


@pytest.mark.parametrize("surfaces_first", [False, True])
def test_parent_gone_while_detecting_ends_the_worker_quietly(rng, surfaces_first):
    """A node stopped by SIGTERM/SIGINT closes its connection while the worker detects; the
    worker's reply then meets a closed socket: it ends with exit code 0 and prints nothing
    (it printed BrokenPipeError tracebacks, 2 of 6 signals on a loaded node)."""
    import socket
    from multiprocessing.connection import Connection

    parent, child = socket.socketpair()
    proc = subprocess.Popen(
        [sys.executable, "-m", "supportnode.node.worker", str(child.fileno())],
        pass_fds=(child.fileno(),),
        stdin=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    child.close()
    conn = Connection(parent.detach())
    conn.send(DetectParams())
    assert conn.poll(60) and conn.recv()[0] == "ready"
    pts = np.concatenate([_scene(rng) + (5.0 * i, 0.0, 0.0) for i in range(4)])
    conn.send((pts.shape, pts.dtype.str, surfaces_first, None))
    conn.send_bytes(np.ascontiguousarray(pts))
    conn.close()  # at once: the worker is detecting
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and "Traceback" not in err and "Error" not in err, err


def test_worker_entry_point_without_a_descriptor_is_a_usage_error():
    r = subprocess.run(
        [sys.executable, "-m", "supportnode.node.worker"], capture_output=True, text=True
    )
    assert r.returncode == 2
    assert "usage" in r.stderr and "Traceback" not in r.stderr


def test_node_that_loses_its_worker_goes_on_detecting(rng, caplog):
    """Over sockets: detections go to the worker; when it is killed, the node logs it, counts
    it and detects in its own thread, and results keep coming."""
    pub = Publisher("tcp://127.0.0.1:*", "scan", hwm=100)
    p = DetectParams()
    node_p = dataclasses.replace(
        p.node, scan_endpoint=pub.endpoint, pub_endpoint="tcp://127.0.0.1:*", map_period=0.0
    )
    pose = np.eye(4)
    pose[:3, 3] = (0.0, 0.0, 1.5)
    pts = (_scene(rng) - pose[:3, 3]).astype(np.float32)
    cloud = PointCloud.from_xyz(pts, 0.0, "lidar", pose=pose_from_matrix(pose))
    got: list[SupportSurfaces] = []

    def send_and_wait(k: int) -> None:
        stamp = 1.0 + 0.1 * k
        pub.publish(dataclasses.replace(cloud, stamp=stamp, seq=k + 1))
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            msg = sub.recv(0.2)
            if isinstance(msg, SupportSurfaces) and msg.stamp == pytest.approx(stamp):
                got.append(msg)
                # Surfaces go out first: the detection ends when its obstacles are described.
                while node.counters["detections"] < len(got):
                    assert time.monotonic() < deadline, f"detection {k} did not end"
                    time.sleep(0.01)
                return
        raise AssertionError(f"no surfaces for scan {k}")

    with Node(dataclasses.replace(p, node=node_p)) as node:
        node.open()
        sub = Subscriber("surfaces", node.pub_endpoint, keep_newest=100)
        th = threading.Thread(target=node.spin, kwargs={"handle_signals": False}, daemon=True)
        th.start()
        try:
            time.sleep(0.5)  # slow joiner
            deadline = time.monotonic() + 60
            while node._worker is None or not node._worker.ready():
                assert time.monotonic() < deadline, "worker did not start"
                time.sleep(0.05)
            send_and_wait(0)
            assert node.counters["worker_detections"] == 1
            assert node.diagnostics().gauges["rss_mb_worker"] > 0
            os.kill(node._worker.pid, signal.SIGKILL)
            time.sleep(0.2)
            with caplog.at_level("WARNING", logger="supportnode.node"):
                send_and_wait(1)
            send_and_wait(2)
            c = node.diagnostics().counters
        finally:
            node.stop()
            th.join(5)
            sub.close()
            pub.close()
    assert not th.is_alive()
    assert c["worker_failures"] == 1 and c["worker_detections"] == 1
    assert c["detections"] == 3
    assert any("detection worker died" in r.getMessage() for r in caplog.records)
    for msg in got:
        assert sorted(round(s.height, 2) for s in msg.surfaces) == [0.0, 0.75]


def test_surfaces_first_part_then_the_whole_detection(rng):
    """Asked for surfaces first, the worker sends the surfaces and their free space before it
    describes the objects; they equal the final result's. A failing callback in the parent
    does not leave the final reply to be taken for the next detection's."""
    pts = _scene(rng)
    want = incremental.full(pts, DetectParams())
    parts: list[incremental.Items] = []
    w = _started()
    try:
        got = w.detect(pts, on_surfaces=parts.append)
        assert len(parts) == 1 and parts[0].clusters == []
        assert [s.to_dict() for s in parts[0].surfaces] == [s.to_dict() for s in want.surfaces]
        assert [f.to_dict() for f in parts[0].free] == [f.to_dict() for f in want.free]
        _same(got, want)

        def fail(_: incremental.Items) -> None:
            raise ValueError("planner gone")

        with pytest.raises(ValueError, match="planner gone"):
            w.detect(pts, on_surfaces=fail)
        shifted = pts + (1.0, 0.0, 0.0)
        _same(w.detect(shifted), incremental.full(shifted, DetectParams()))
    finally:
        w.close()


@pytest.mark.parametrize("surfaces_first", [False, True])
def test_on_sent_runs_once_the_worker_has_the_points(rng, surfaces_first):
    """on_sent runs while the worker detects: the caller may change its points from then on
    (the node clears its map then). A failing on_sent does not leave the worker's replies to be
    taken for the next detection's."""
    pts = _scene(rng)
    want = incremental.full(pts, DetectParams())
    parts: list[incremental.Items] = []
    on_surfaces = parts.append if surfaces_first else None
    calls = []
    w = _started()
    try:
        mine = pts.copy()

        def overwrite() -> None:
            calls.append(len(parts))
            mine[:] = 0.0  # sent already: the worker detects on what it got

        _same(w.detect(mine, on_surfaces=on_surfaces, on_sent=overwrite), want)
        assert calls == [0] and len(parts) == int(surfaces_first)

        def fail() -> None:
            raise ValueError("map gone")

        with pytest.raises(ValueError, match="map gone"):
            w.detect(pts, on_surfaces=on_surfaces, on_sent=fail)
        shifted = pts + (1.0, 0.0, 0.0)
        _same(w.detect(shifted, on_surfaces=on_surfaces), incremental.full(shifted, DetectParams()))
    finally:
        w.close()
