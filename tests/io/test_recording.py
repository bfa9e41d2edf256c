"""MCAP recordings: message packing, writer/reader round trip, seeking, damaged files, and the
`supportnode record` command (clean stop and a hard-killed recorder)."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest

from supportnode.client import Publisher
from supportnode.io.recording import (
    McapFile,
    RecordingError,
    RecordingWriter,
    pack_message,
    unpack_message,
)
from supportnode.msgs import Diagnostics, LatencyStats, PointCloud, decode_any, peek_header

REPO = Path(__file__).resolve().parents[2]


def as_bytes(frames) -> list[bytes]:
    return [bytes(memoryview(f).cast("B")) if memoryview(f).nbytes else b"" for f in frames]


def cloud_frames(i: int, n: int = 500, topic: str = "scan") -> list:
    rng = np.random.default_rng(i)
    return PointCloud.from_xyz(
        rng.normal(size=(n, 3)).astype(np.float32),
        stamp=1000.0 + 0.1 * i,
        frame_id="lidar",
        seq=i,
        fields={"intensity": rng.integers(0, 255, n).astype(np.uint8)},
        pose=(np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, 0.0, 1.0])),
    ).encode(topic)


def diag_frames(i: int) -> list:
    return Diagnostics(
        stamp=1000.0 + i,
        frame_id="",
        seq=i,
        node="n",
        level="ok",
        message="",
        counters={"scans": i},
        latencies={"total": LatencyStats(0.01, 0.02)},
        gauges={},
    ).encode("diagnostics")


def write_recording(path: Path, count: int = 30, **kwargs) -> list[list[bytes]]:
    """Scans every 0.1 s and diagnostics every 1 s; returns the frames written, in order."""
    written = []
    with RecordingWriter(path, **kwargs) as w:
        for i in range(count):
            frames = cloud_frames(i)
            w.write(frames, receive_time=1000.0 + 0.1 * i)
            written.append(as_bytes(frames))
            if i % 10 == 0:
                frames = diag_frames(i)
                w.write(frames, receive_time=1000.0 + 0.1 * i + 0.01)
                written.append(as_bytes(frames))
    return written


def test_pack_unpack_round_trip() -> None:
    big = np.arange(70_000, dtype=np.uint8)  # bin32
    mid = np.arange(300, dtype=np.uint8)  # bin16
    arrays = [
        ("x", np.zeros(3, np.float32)),
        ("y", np.zeros(3, np.float32)),
        ("z", np.ones(3, np.float32)),
    ]
    arrays += [
        (f"f{i}", big if i == 0 else mid if i == 1 else np.zeros(3, np.uint8)) for i in range(20)
    ]
    arrays.append(("empty", np.zeros((0, 2), np.uint8)))
    # 24 buffers: the msgpack array needs its 16-bit length form.
    frames = PointCloud.from_xyz(np.zeros((3, 3), np.float32), 1.0, "f").encode("scan")
    from supportnode.msgs._wire import encode_frames

    frames = encode_frames("scan", "PointCloud", 1.0, "f", 0, arrays)
    data = pack_message(frames)
    back = unpack_message("scan", data)
    assert as_bytes(back) == as_bytes(frames)
    # It is one msgpack value any msgpack library reads: [header map, bin, bin, ...].
    generic = msgpack.unpackb(data, raw=False)
    assert generic[0]["type"] == "PointCloud" and generic[4 + 0] == big.tobytes()
    for bad in (b"", b"\x91", b"\x80", data[:-1], data + b"\x00", b"\x92\x80\xd9"):
        with pytest.raises(RecordingError):
            unpack_message("scan", bad)


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_writer_reader_round_trip(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "rec.mcap"
    written = write_recording(path, compression=compression, chunk_size=20_000)
    with McapFile(path) as f:
        assert f.indexed and not f.warnings
        assert f.stats.message_count == len(written) and f.stats.chunk_count > 3
        assert f.stats.compression == {compression}
        msgs = list(f.messages())
        types = {ch.topic: ch.type for ch in f.channels.values()}
        assert types == {"scan": "PointCloud", "diagnostics": "Diagnostics"}
        ch = next(c for c in f.channels.values() if c.topic == "scan")
        schema = json.loads(ch.schema_data)
        assert ch.schema_encoding == "jsonschema" and schema["title"] == "supportnode/PointCloud"
        assert f.metadata["supportnode"]["protocol_version"] == "1"
    assert [as_bytes(m.frames()) for m in msgs] == written
    scans = [m for m in msgs if m.channel.topic == "scan"]
    assert [m.log_time for m in scans] == [round((1000.0 + 0.1 * i) * 1e9) for i in range(30)]
    assert [m.publish_time for m in scans] == [round((1000.0 + 0.1 * i) * 1e9) for i in range(30)]
    assert isinstance(decode_any(scans[3].frames()), PointCloud)


def test_readable_by_the_mcap_library(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    path = tmp_path / "rec.mcap"
    written = write_recording(path, count=5)
    with open(path, "rb") as f:
        reader = make_reader(f)
        got = [(c.topic, c.message_encoding, s.name, m.data) for s, c, m in reader.iter_messages()]
    assert [g[0] for g in got] == ["scan", "diagnostics", "scan", "scan", "scan", "scan"]
    assert got[0][1:3] == ("msgpack", "supportnode/PointCloud")
    assert as_bytes(unpack_message("scan", got[0][3])) == written[0]


def test_seeking_by_time_and_topic(tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    write_recording(path, chunk_size=10_000)
    with McapFile(path) as f:
        start = round(1001.5e9)
        msgs = list(f.messages(topics=["scan"], start=start, end=round(1002.0e9)))
        assert [peek_header(m.frames()).seq for m in msgs] == [15, 16, 17, 18, 19]
        assert [m.channel.topic for m in f.messages(topics=["diagnostics"])] == ["diagnostics"] * 3


def test_truncated_files_read_up_to_the_damage(tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    written = write_recording(path, chunk_size=10_000)
    data = path.read_bytes()
    for cut in (len(data) - 3, len(data) * 3 // 4, len(data) // 3, 40):
        part = tmp_path / f"cut{cut}.mcap"
        part.write_bytes(data[:cut])
        with McapFile(part) as f:
            got = [as_bytes(m.frames()) for m in f.messages()]
            warnings = list(f.warnings)
        assert got == written[: len(got)]  # a prefix, nothing invented
        assert len(warnings) == 1 and "\n" not in warnings[0]
        assert "not finalised" in warnings[0] and str(part) in warnings[0]
    with McapFile(tmp_path / f"cut{len(data) * 3 // 4}.mcap") as f:
        assert len(list(f.messages())) > len(written) // 2


def test_corrupt_chunk_is_skipped(tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    written = write_recording(path, chunk_size=10_000)
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with McapFile(path) as f:
        got = [as_bytes(m.frames()) for m in f.messages()]
        assert len(f.warnings) == 1 and "corrupt" in f.warnings[0]
    assert 0 < len(written) - len(got) < 10
    assert all(g in written for g in got)


def test_foreign_files_one_line(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(b"PK\x03\x04 not an mcap file at all")
    with pytest.raises(RecordingError, match=r"x\.mcap: not an MCAP file \(bad magic bytes\)$"):
        McapFile(tmp_path / "x.mcap")
    with pytest.raises(RecordingError, match="no such file"):
        McapFile(tmp_path / "missing.mcap")


def _start_recorder(path: Path, endpoint: str, *extra: str) -> subprocess.Popen:
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "supportnode",
            "record",
            "-o",
            str(path),
            "--endpoint",
            endpoint,
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )
    assert proc.stderr is not None
    line = proc.stderr.readline()  # "record: recording ... " once subscribed
    assert line.startswith("record: recording"), line
    return proc


def _publish(pub: Publisher, n: int, hz: float) -> list[list[bytes]]:
    sent = []
    time.sleep(0.3)  # the recorder's subscription reaches the publisher
    t0 = time.monotonic()
    for i in range(n):
        frames = cloud_frames(i + 1, n=2000)
        pub._pub.send(frames)
        sent.append(as_bytes(frames))
        time.sleep(max(0.0, t0 + (i + 1) / hz - time.monotonic()))
    return sent


def test_record_command_sigterm_finalises(tmp_path: Path) -> None:
    path = tmp_path / "live.mcap"
    with Publisher("tcp://127.0.0.1:*", "scan") as pub:
        proc = _start_recorder(path, pub.endpoint, "scan")
        sent = _publish(pub, 20, 50.0)
        time.sleep(0.3)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert "20 messages" in out and "dropped 0 (sequence gaps)" in out
    with McapFile(path) as f:
        assert f.indexed and not f.warnings
        assert [as_bytes(m.frames()) for m in f.messages()] == sent


def test_hard_killed_recorder_file_reads_to_last_chunk(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    with Publisher("tcp://127.0.0.1:*", "scan") as pub:
        proc = _start_recorder(path, pub.endpoint, "--flush", "0.2")
        sent = _publish(pub, 40, 40.0)
        time.sleep(0.5)  # > --flush: the last chunk is on disk
        proc.kill()
        proc.communicate(timeout=20)
    with McapFile(path) as f:
        got = [as_bytes(m.frames()) for m in f.messages()]
        warnings = list(f.warnings)
    assert not McapFile(path).indexed
    assert len(warnings) == 1 and "not finalised (recorder killed?)" in warnings[0]
    assert got == sent  # flushed every 0.2 s, also when idle: nothing lost
    # The command line tools say the same in one line and list what is there.
    res = subprocess.run(
        [sys.executable, "-m", "supportnode", "info", str(path)],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
    )
    assert res.returncode == 0
    assert re.search(rf"^scan +PointCloud +{len(sent)} ", res.stdout, re.M), res.stdout
    assert res.stderr.count("\n") == 1 and "not finalised" in res.stderr
    assert os.path.getsize(path) > 0
