"""`info` on foreign MCAP files, `echo`'s stamp ages and its word while it waits."""

from __future__ import annotations

import re
import socket
from pathlib import Path

import numpy as np
from conftest import run_cli
from mcap.writer import Writer

from supportnode.cli.echo import format_message
from supportnode.msgs import PointCloud

REPO = Path(__file__).resolve().parents[2]


def _foreign_mcap(path: Path) -> None:
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        tf = w.register_schema("foxglove.FrameTransform", "protobuf", b"\x00")
        imu = w.register_schema("sensor_msgs/msg/Imu", "ros2msg", b"float64 x")
        ch_tf = w.register_channel("tf", "protobuf", tf)
        ch_imu = w.register_channel("/imu", "cdr", imu)
        for i in range(8):
            t = 1_000_000_000 + i * 100_000_000
            w.add_message(ch_tf, log_time=t, data=b"x" * 10, publish_time=t)
        for i in range(3):
            t = 1_000_000_000 + i * 200_000_000
            w.add_message(ch_imu, log_time=t, data=b"y" * 4, publish_time=t)
        w.finish()


def test_info_lists_channels_it_cannot_play(tmp_path: Path) -> None:
    path = tmp_path / "foxglove.mcap"
    _foreign_mcap(path)
    res = run_cli("info", str(path))
    assert res.returncode == 0, res.stderr
    assert "none playable" not in res.stdout
    assert "messages:  11 over 0.700 s" in res.stdout
    assert "playable:  0 " in res.stdout
    assert re.search(
        r"^tf +foxglove\.FrameTransform \(protobuf\) +8 +10\.00 Hz +80 B", res.stdout, re.M
    )
    assert re.search(r"^/imu +sensor_msgs/msg/Imu \(cdr\) +3 +5\.00 Hz +12 B", res.stdout, re.M)


def test_info_on_our_recording_counts_playable_topics() -> None:
    res = run_cli("info", "sim_scans/shelf_lidar.mcap")
    assert res.returncode == 0
    assert re.search(r"^scan +PointCloud +5 +10\.00 Hz", res.stdout, re.M), res.stdout
    assert "playable:" not in res.stdout  # everything plays


def test_echo_shows_age_only_for_stamps_near_now() -> None:
    cloud = PointCloud.from_xyz(np.zeros((2, 3), np.float32), stamp=1000.0, frame_id="lidar")
    assert "age" not in format_message(cloud, "scan", 10, received=1_796_181_612.8)
    near = format_message(cloud, "scan", 10, received=1000.25)
    assert "(age 0.250 s)" in near


def test_echo_says_what_it_waits_for_after_two_seconds() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    res = run_cli("echo", "surfaces", "--endpoint", f"tcp://127.0.0.1:{port}", "--timeout", "3")
    assert res.returncode == 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith(
        f"supportnode echo: waiting for messages on topic 'surfaces' from tcp://127.0.0.1:{port} "
        "(nothing for 2 s"
    )
