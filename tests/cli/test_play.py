"""`supportnode play`: record -> play round trip message for message (bytes, order, timing at
rate 1 and 5), seeking with --start, topic selection and remapping, folder sources, damaged
files, and the committed sim_scans recordings."""

from __future__ import annotations

import itertools
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zmq

from supportnode.cli import main
from supportnode.client import Publisher
from supportnode.io.clouds import write_cloud
from supportnode.io.recording import McapFile
from supportnode.io.sources import FolderSource, open_source
from supportnode.msgs import Diagnostics, LatencyStats, PointCloud

REPO = Path(__file__).resolve().parents[2]


def as_bytes(frames) -> list[bytes]:
    return [bytes(memoryview(f).cast("B")) if memoryview(f).nbytes else b"" for f in frames]


def free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{s.getsockname()[1]}"


class Catcher(threading.Thread):
    """Binds a SUB socket to ``endpoint`` and keeps (arrival time, frames) of every message."""

    def __init__(self, endpoint: str, expect: int, timeout: float = 20.0) -> None:
        super().__init__(daemon=True)
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.SUB)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.setsockopt(zmq.RCVHWM, 0)
        self.sock.setsockopt(zmq.SUBSCRIBE, b"")
        self.sock.bind(endpoint)  # play connects to it, as to a node that binds
        self.expect, self.timeout = expect, timeout
        self.got: list[tuple[float, list[bytes]]] = []
        self.start()

    def run(self) -> None:
        deadline = time.monotonic() + self.timeout
        while len(self.got) < self.expect and time.monotonic() < deadline:
            if self.sock.poll(50):
                frames = self.sock.recv_multipart()
                self.got.append((time.monotonic(), frames))

    def result(self) -> list[tuple[float, list[bytes]]]:
        self.join(self.timeout + 5)
        self.sock.close(linger=0)
        self.ctx.term()
        return self.got


def play(path: Path | str, *args: str, expect: int) -> tuple[int, list[tuple[float, list[bytes]]]]:
    endpoint = free_endpoint()
    catcher = Catcher(endpoint, expect)
    rc = main(
        ["play", str(path), "--endpoint", endpoint, "--connect", "--wait", "0.3", "--quiet", *args]
    )
    return rc, catcher.result()


def scan(i: int) -> list:
    rng = np.random.default_rng(i)
    return PointCloud.from_xyz(
        rng.normal(size=(3000, 3)).astype(np.float32), stamp=time.time(), frame_id="lidar", seq=i
    ).encode("scan")


def diag(i: int) -> list:
    return Diagnostics(
        stamp=time.time(), frame_id="", seq=i, node="n", level="ok", message="",
        counters={"scans": i}, latencies={"total": LatencyStats(0.01, 0.02)}, gauges={},
    ).encode("diagnostics")  # fmt: skip


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[Path, list[list[bytes]]]:
    """A live recording by `supportnode record`: 16 scans and 4 diagnostics at 20 Hz, in
    chunks of 100 kB (about 3 messages)."""
    path = tmp_path_factory.mktemp("rec") / "live.mcap"
    with Publisher("tcp://127.0.0.1:*", "scan", hwm=1000) as pub:
        proc = subprocess.Popen(
            [sys.executable, "-m", "supportnode", "record", "-o", str(path), "--endpoint", pub.endpoint,
             "--chunk-size", "0.1"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        )  # fmt: skip
        assert proc.stderr is not None and proc.stderr.readline().startswith("record: recording")
        time.sleep(0.3)
        sent = []
        t0 = time.monotonic()
        for i in range(20):
            frames = scan(i + 1) if i % 5 else diag(i // 5 + 1)
            pub._pub.send(frames)
            sent.append(as_bytes(frames))
            time.sleep(max(0.0, t0 + (i + 1) * 0.05 - time.monotonic()))
        time.sleep(0.3)
        proc.terminate()
        _out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    return path, sent


@pytest.mark.parametrize("rate", [1.0, 5.0])
def test_record_play_round_trip(recorded, rate: float) -> None:
    path, sent = recorded
    with McapFile(path) as f:
        log_times = np.array([m.log_time for m in f.messages()]) * 1e-9
    rc, got = play(path, "--rate", str(rate), expect=len(sent))
    assert rc == 0
    assert [frames for _, frames in got] == sent  # every byte, in order
    arrival = np.array([t for t, _ in got])
    expected = (log_times - log_times[0]) / rate
    # Play waits until each message is due: none comes early, whatever the host's load; lateness
    # is the scheduler's (a loaded host delays a wake-up), so it is bounded loosely.
    error = (arrival - arrival[0]) - expected
    assert error.min() > -0.05, error  # (the first arrival, the reference, may itself be late)
    assert np.median(error) < 0.1 and error.max() < 0.5, error


def test_seeking_with_start_and_duration(recorded) -> None:
    path, _sent = recorded
    rc, got = play(path, "--start", "0.42", "--duration", "0.3", expect=6)
    assert rc == 0
    with McapFile(path) as f:
        t0 = f.stats.start_time
        want = [
            as_bytes(m.frames()) for m in f.messages() if t0 + 0.42e9 <= m.log_time < t0 + 0.72e9
        ]
    assert 4 <= len(want) <= 7
    assert [frames for _, frames in got] == want


def test_topics_and_remap(recorded) -> None:
    path, sent = recorded
    rc, got = play(
        path, "--topics", "diagnostics", "--remap", "diagnostics:=diag", "--rate", "5", expect=4
    )
    assert rc == 0
    assert [frames[0] for _, frames in got] == [b"diag"] * 4
    assert [frames[1:] for _, frames in got] == [s[1:] for s in sent if s[0] == b"diagnostics"]


def test_truncated_recording_plays_what_is_readable(recorded, tmp_path: Path, capsys) -> None:
    path, sent = recorded
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    with McapFile(cut) as f:
        readable = len(list(f.messages()))
    assert 0 < readable < len(sent)
    rc, got = play(cut, "--rate", "10", expect=readable)
    assert rc == 0
    assert [frames for _, frames in got] == sent[:readable]
    err = capsys.readouterr().err
    assert err.count("warning:") == 1 and "not finalised" in err


def test_bad_sources_one_line(tmp_path: Path, capsys) -> None:
    (tmp_path / "junk.mcap").write_bytes(b"\x00" * 100)
    for target, text in (
        (tmp_path / "junk.mcap", "not an MCAP file"),
        (tmp_path / "missing.bag", "no such file"),
        (tmp_path / "notes.txt.gz", "unknown recording type"),
    ):
        if target.suffix == ".gz":
            target.write_bytes(b"x")
        assert main(["play", str(target), "--endpoint", free_endpoint()]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and text in err


def test_folder_of_clouds_source(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    clouds = [rng.normal(size=(100 + i, 3)) for i in range(4)]
    for i, pts in enumerate(clouds):
        write_cloud(tmp_path / f"scan_{i}.{'ply' if i % 2 else 'pcd'}", pts)
    (tmp_path / "notes.md").write_text("ignored")
    with open_source(tmp_path, hz=5.0, topic="cloud", frame_id="odom") as src:
        assert isinstance(src, FolderSource) and src.topics() == {"cloud": "PointCloud"}
        msgs = list(src.messages())
        assert [m.time for m in msgs] == pytest.approx([0.0, 0.2, 0.4, 0.6])
        assert [m.time for m in src.messages(start=0.3)] == pytest.approx([0.4, 0.6])
    for m, pts in zip(msgs, clouds, strict=True):
        cloud = m.decode()
        assert m.topic == "cloud" and cloud.frame_id == "odom"
        np.testing.assert_allclose(cloud.points, pts, atol=1e-6)


def test_sim_scans_recordings_match_their_npz_frames() -> None:
    """The committed MCAPs are what `sh sim_scans/make.sh` makes from the NPZ folders."""
    for name in ("shelf_lidar", "table_chairs_lidar"):
        with (
            open_source(REPO / "sim_scans" / name) as folder,
            open_source(REPO / "sim_scans" / f"{name}.mcap") as rec,
        ):
            a, b = list(folder.messages()), list(rec.messages())
        assert len(a) == len(b) == 5
        assert [as_bytes(m.frames) for m in a] == [as_bytes(m.frames) for m in b]
        assert [m.time for m in b] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
        cloud = b[1].decode()
        assert cloud.frame_id == "lidar" and cloud.pose is not None
        # Back in the world frame, the points are the simulator's.
        with np.load(REPO / "sim_scans" / name / "frame_001.npz") as z:
            pose, world = z["sensor_pose"], z["points"]
        np.testing.assert_allclose(cloud.points @ pose[:3, :3].T + pose[:3, 3], world, atol=1e-4)


def test_info_lists_a_recording(recorded, capsys) -> None:
    path, _ = recorded
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "indexed" in out and "zstd" in out
    lines = {
        line.split()[0]: line.split()
        for line in out.splitlines()
        if line.startswith(("scan", "diagnostics"))
    }
    assert lines["scan"][1:3] == ["PointCloud", "16"] and lines["diagnostics"][1:3] == [
        "Diagnostics",
        "4",
    ]
    # 16 scans over 0.9 s (every 50 ms, but for the 4 diagnostics' slots): 15 / 0.9 = 16.7 Hz
    assert lines["scan"][4] == "Hz" and abs(float(lines["scan"][3]) - 16.7) < 1.5


@pytest.mark.parametrize(("extra", "moving"), [((), True), (("--no-restamp",), False)])
def test_looped_replay_keeps_time_moving_by_default(extra, moving: bool) -> None:
    # A node resets its map when a stamp goes back ("source restarted"): a loop must not.
    import signal

    from supportnode.msgs import decode_any

    endpoint = free_endpoint()
    catcher = Catcher(endpoint, 12)
    proc = subprocess.Popen(
        [sys.executable, "-m", "supportnode", "play", str(REPO / "sim_scans" / "shelf_lidar.mcap"),
         "--loop", "--rate", "4", "--endpoint", endpoint, "--connect", "--wait", "0.3", "--quiet",
         *extra],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        got = catcher.result()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=20)
    stamps = [decode_any(frames).stamp for _, frames in got]
    assert len(stamps) == 12  # two passes of 5 and more
    assert all(b > a for a, b in itertools.pairwise(stamps)) == moving, stamps
