"""Client library over real sockets: decoded messages by iterator, recv and callback, malformed
messages skipped and counted; and the examples run as subprocesses, stopped by SIGINT."""

from __future__ import annotations

import dataclasses
import math
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from supportnode import bus
from supportnode.client import Publisher, Subscriber, pose_from_matrix
from supportnode.errors import InputError
from supportnode.msgs import (
    Limits,
    ObstacleCluster,
    ObstacleClusters,
    PointCloud,
    SupportSurface,
    SupportSurfaces,
)

REPO = Path(__file__).resolve().parents[1]


def surface(id_, height, disc_radius, safe=True):
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    return SupportSurface(
        id=id_,
        height=height,
        normal=np.array([0.0, 0.0, 1.0]),
        area=1.0,
        outline=[square],
        free_area=0.6,
        disc_center=np.array([0.5, 0.5]),
        disc_radius=disc_radius,
        safe=safe,
    )


def cluster(id_, surface_id):
    c = np.array([0.2, 0.2, 0.8])
    return ObstacleCluster(
        id=id_,
        surface_id=surface_id,
        centroid=c,
        bbox_min=c - 0.05,
        bbox_max=c + 0.05,
        obb_center=c,
        obb_size=np.full(3, 0.1),
        obb_yaw=0.0,
        height=0.1,
        point_count=40,
    )


def wait_connected(pub: Publisher, sub: Subscriber, send) -> None:
    """Publish until the subscriber receives (ZeroMQ's slow joiner), then empty its queue."""
    deadline = time.monotonic() + 5
    while sub.recv(0.02) is None:
        assert time.monotonic() < deadline, "subscriber never connected"
        send()
    while sub.recv(0.05) is not None:
        pass


@pytest.fixture
def pub():
    with Publisher("tcp://127.0.0.1:*", "scan") as p:
        yield p


def test_publish_cloud_round_trip(pub, rng):
    points = rng.normal(size=(1000, 3)).astype(np.float32)
    pose = np.eye(4)
    pose[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90 deg about z
    pose[:3, 3] = [1, 2, 3]
    with Subscriber("scan", pub.endpoint, timeout=2.0) as sub:
        wait_connected(pub, sub, lambda: pub.publish_cloud(points[:1]))
        sent = pub.publish_cloud(
            points,
            stamp=12.5,
            frame_id="lidar",
            fields={"intensity": np.arange(1000, dtype=np.float32)},
            pose=pose,
            gravity=[0, 0, -9.81],
        )
        msg = sub.recv(2.0)
    assert isinstance(msg, PointCloud)
    assert msg.seq == sent.seq and msg.stamp == 12.5 and msg.frame_id == "lidar"
    np.testing.assert_array_equal(msg.points, points.astype(np.float64))
    np.testing.assert_array_equal(msg.fields["intensity"], np.arange(1000))
    np.testing.assert_allclose(msg.pose.translation, [1, 2, 3])
    s = math.sqrt(0.5)
    np.testing.assert_allclose(msg.pose.rotation, [0, 0, s, s], atol=1e-12)
    np.testing.assert_allclose(msg.gravity, [0, 0, -9.81])


def test_iterator_stops_on_timeout(pub):
    with Subscriber("scan", pub.endpoint, timeout=0.3, keep_newest=10) as sub:
        wait_connected(pub, sub, lambda: pub.publish_cloud(np.zeros((1, 3))))
        for _ in range(3):
            pub.publish_cloud(np.zeros((5, 3)))
            time.sleep(0.02)  # a consumer keeping up: nothing dropped
        t0 = time.monotonic()
        got = list(sub)
        assert time.monotonic() - t0 < 2.0
    assert [m.count for m in got] == [5, 5, 5]
    assert [m.seq for m in got] == sorted(m.seq for m in got)


def test_spin_callback_and_duration(pub):
    with Subscriber("scan", pub.endpoint) as sub:
        wait_connected(pub, sub, lambda: pub.publish_cloud(np.zeros((1, 3))))
        seen = []
        stop = threading.Event()

        def feed():
            while not stop.is_set():
                pub.publish_cloud(np.zeros((2, 3)))
                time.sleep(0.02)

        # Sockets are not thread-safe: this publisher is used only by the feeder from now on.
        feeder = threading.Thread(target=feed)
        feeder.start()
        try:
            t0 = time.monotonic()
            handled = sub.spin(seen.append, duration=0.4)
            elapsed = time.monotonic() - t0
        finally:
            stop.set()
            feeder.join()
    assert 0.35 < elapsed < 1.5
    assert handled == len(seen) >= 3
    assert all(isinstance(m, PointCloud) for m in seen)


def test_recv_timeout_none_when_silent():
    with Subscriber("scan", "inproc://silent-client") as sub:
        t0 = time.monotonic()
        assert sub.recv(0.05) is None
        assert time.monotonic() - t0 < 0.5


@pytest.mark.parametrize(
    "frames, error",
    [
        ([b"scan", b"\xc1 not msgpack"], "topic 'scan'"),
        ([b"scan"], "topic 'scan'"),
        ([b"scan", b"\x80"], "topic 'scan'"),  # empty msgpack map: no type
    ],
)
def test_malformed_messages_are_skipped_and_counted(frames, error):
    with (
        bus.Publisher("tcp://127.0.0.1:*") as raw,
        Subscriber("scan", raw.endpoint, keep_newest=10) as sub,
    ):
        good = PointCloud.from_xyz(np.ones((3, 3)), stamp=1.0, frame_id="m").encode("scan")
        wait_connected(None, sub, lambda: raw.send(good))  # type: ignore[arg-type]
        raw.send(frames)
        raw.send(good)
        msg = sub.recv(2.0)
    assert isinstance(msg, PointCloud) and msg.count == 3
    assert sub.rejected == 1
    assert sub.last_error is not None and error in sub.last_error


def test_oversized_messages_are_rejected(pub):
    limits = Limits(max_message_bytes=2000)
    with Subscriber("scan", pub.endpoint, limits=limits, keep_newest=5) as sub:
        wait_connected(pub, sub, lambda: pub.publish_cloud(np.zeros((1, 3))))
        # Each frame (800 B of float64 x, y or z) is within the limit, the message is not.
        pub.publish_cloud(np.zeros((100, 3)))
        pub.publish_cloud(np.zeros((2, 3)))
        msg = sub.recv(2.0)
        assert msg is not None and msg.count == 2
        assert sub.rejected == 1
        assert "exceeds max_message_bytes 2000" in (sub.last_error or "")
        # A single frame above the limit too; the connection survives it (ZMQ_MAXMSGSIZE
        # would have closed it for good).
        pub.publish_cloud(np.zeros((1000, 3)))
        pub.publish_cloud(np.zeros((4, 3)))
        msg = sub.recv(2.0)
        assert msg is not None and msg.count == 4
        assert sub.rejected == 2


def test_pose_from_matrix_rejects_non_rotations():
    with pytest.raises(InputError, match="not a rotation"):
        pose_from_matrix(np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(InputError, match="4x4"):
        pose_from_matrix(np.eye(3))
    rng = np.random.default_rng(0)
    for _ in range(20):  # every branch of the conversion: random rotations
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        x, y, z, w = q
        r = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        m = np.eye(4)
        m[:3, :3] = r
        got = pose_from_matrix(m).rotation
        assert min(np.abs(got - q).max(), np.abs(got + q).max()) < 1e-9


# ---------------------------------------------------------------------------------------------
# Examples as subprocesses


class Lines:
    """A subprocess's stdout lines, read by a thread so the test can wait for one."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self.lines: queue.SimpleQueue[str] = queue.SimpleQueue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def wait_for(self, predicate, timeout: float, on_idle=None) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.05)
            except queue.Empty:
                if on_idle is not None:
                    on_idle()
                continue
            self.seen.append(line)
            if predicate(line):
                return line
        raise AssertionError("expected line not printed; got:\n" + "\n".join(self.seen))


def run_example(name: str, *args: str, sigint: object = signal.SIG_DFL) -> subprocess.Popen[str]:
    """The example as a subprocess; sigint: the SIGINT disposition it starts with (pytest run
    as a background job of a script has SIGINT ignored, and its children inherit that)."""
    return subprocess.Popen(
        [sys.executable, str(REPO / "examples" / name), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        preexec_fn=lambda: signal.signal(signal.SIGINT, sigint),
    )


@pytest.mark.parametrize("name", ["planner.py", "echo.py"])
def test_example_started_with_sigint_ignored_still_stops_on_sigint(name):
    """A background job of a shell script starts with SIGINT ignored: the examples must still
    end on SIGINT (as `supportnode launch` and a user's kill -INT stop them), exit code 0."""
    with bus.Publisher("tcp://127.0.0.1:*") as probe:
        endpoint = probe.endpoint
    proc = run_example(name, "--endpoint", endpoint, sigint=signal.SIG_IGN)
    try:
        time.sleep(3.0)  # imports done, subscribed: waiting for messages
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        pytest.fail(f"{name} ignored SIGINT: {err}")
    assert proc.returncode == 0, err
    assert "Traceback" not in err


@pytest.mark.parametrize("surfaces_first", [True, False])
def test_planner_prints_what_fits_and_exits_0_on_sigint(surfaces_first):
    """The planner pairs a detection's surfaces and obstacles by seq, in either order."""
    with Publisher("tcp://127.0.0.1:*", "surfaces") as pub:
        obstacles = ObstacleClusters(stamp=5.0, frame_id="map", seq=7, clusters=[cluster(11, 3)])
        surfaces = SupportSurfaces(
            stamp=5.0,
            frame_id="map",
            seq=7,
            surfaces=[surface(3, 0.73, 0.30), surface(4, 0.45, 0.10), surface(5, 0.0, 2.0, False)],
        )

        def publish():
            # One socket, two topics, like the node; first the obstacles of an older detection.
            pub.publish(dataclasses.replace(obstacles, seq=6, clusters=[]), topic="obstacles")
            if surfaces_first:
                pub.publish(surfaces)
            pub.publish(obstacles, topic="obstacles")
            if not surfaces_first:
                pub.publish(surfaces)

        proc = run_example("planner.py", "--endpoint", pub.endpoint, "--radius", "0.15")
        try:
            out = Lines(proc)
            out.wait_for(lambda s: s.startswith("planner: waiting"), 10)
            # Published until a report shows the obstacle (the first messages may be lost
            # while the planner's subscription travels to the publisher).
            obst = out.wait_for(lambda s: "#11" in s, 10, on_idle=publish)
            no_fit = out.wait_for(lambda s: "surface 4:" in s, 5)
        finally:
            proc.send_signal(signal.SIGINT)
            try:
                _, err = proc.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()  # no process left behind
                _, err = proc.communicate()
    assert proc.returncode == 0, err
    i = len(out.seen) - 1 - out.seen[::-1].index(obst)
    header, fits = out.seen[i - 2], out.seen[i - 1]
    assert header.startswith("seq 7 stamp 5.000 frame map: 2 safe of 3 surfaces")
    assert obst.startswith("    obstacles: ")
    assert fits.endswith(": fits") and "height 0.730 m" in fits and "r 0.300 m" in fits
    assert no_fit.endswith(": does not fit")
    assert "#11 at (0.20, 0.20, 0.80)" in obst
    assert not any("surface 5:" in s for s in out.seen)  # not safe: not offered
    assert "Traceback" not in err


def test_publish_scans_and_echo_examples():
    with bus.Publisher("tcp://127.0.0.1:*") as probe:
        endpoint = probe.endpoint  # a free port, released for the publisher below
    pub = run_example(
        "publish_scans.py", "sim_scans/table_chairs_lidar", "--endpoint", endpoint, "--rate", "50"
    )
    echo = run_example("echo.py", "--endpoint", endpoint, "--topic", "scan")
    try:
        # 30 s: two interpreters importing numpy and scipy on a loaded 2-core runner.
        line = Lines(echo).wait_for(lambda s: s.startswith("scan PointCloud"), 30)
    finally:
        for proc in (echo, pub):
            proc.send_signal(signal.SIGINT)
        outs = []
        for proc in (echo, pub):
            try:
                outs.append(proc.communicate(timeout=10))
            except subprocess.TimeoutExpired:
                proc.kill()  # no process left behind holding the port
                outs.append(proc.communicate())
    assert "points with pose" in line and "frame lidar" in line
    assert echo.returncode == 0 and pub.returncode == 0, outs


def test_publish_scans_frames_are_in_the_sensor_frame():
    sys.path.insert(0, str(REPO / "examples"))
    try:
        from publish_scans import load_frames
    finally:
        sys.path.pop(0)
    folder = REPO / "sim_scans" / "table_chairs_lidar"
    points, pose = load_frames(folder)[0]
    world = np.load(folder / "frame_000.npz")["points"]
    np.testing.assert_allclose(points @ pose[:3, :3].T + pose[:3, 3], world, atol=1e-5)
