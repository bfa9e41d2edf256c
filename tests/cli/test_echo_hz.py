"""`supportnode echo` and `supportnode hz` as subprocesses against a test publisher on a random
port: decoded blocks and JSON lines, one stderr line per malformed message, and a measured rate
close to the published one. ZeroMQ's slow joiner drops what is published before the
subscription arrives, so the publisher repeats until the command has what it needs."""

from __future__ import annotations

import json
import queue
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from supportnode.client import Publisher
from supportnode.msgs import SupportSurface, SupportSurfaces

REPO = Path(__file__).resolve().parents[2]


class Cli:
    """A `supportnode` subprocess whose stdout and stderr lines are collected by threads."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "supportnode", *args],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.out: queue.Queue[str] = queue.Queue()
        self.err: queue.Queue[str] = queue.Queue()
        self.stdout: list[str] = []
        self.stderr: list[str] = []
        for stream, q in ((self.proc.stdout, self.out), (self.proc.stderr, self.err)):
            threading.Thread(target=self._pump, args=(stream, q), daemon=True).start()

    @staticmethod
    def _pump(stream, q: queue.Queue[str]) -> None:
        for line in stream:
            q.put(line.rstrip("\n"))

    def collect(self) -> None:
        for q, lines in ((self.out, self.stdout), (self.err, self.stderr)):
            while True:
                try:
                    lines.append(q.get_nowait())
                except queue.Empty:
                    break

    def publish_until(
        self, publish: Callable[[int], None], done: Callable[[], bool], hz: float = 20.0
    ) -> None:
        """Call ``publish(i)`` at ``hz`` until ``done()`` or the process ends (10 s at most)."""
        deadline = time.monotonic() + 10.0
        i = 0
        while time.monotonic() < deadline:
            self.collect()
            if done() or self.proc.poll() is not None:
                return
            publish(i)
            i += 1
            time.sleep(1.0 / hz)
        pytest.fail(f"timed out; stdout {self.stdout[-5:]} stderr {self.stderr[-5:]}")

    def finish(self, timeout: float = 5.0) -> int:
        try:
            rc = self.proc.wait(timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
        time.sleep(0.05)  # let the pump threads reach EOF
        self.collect()
        return rc


def surfaces_msg(seq: int) -> SupportSurfaces:
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    return SupportSurfaces(
        stamp=time.time(),
        frame_id="map",
        seq=seq,
        surfaces=[
            SupportSurface(
                id=3,
                height=0.42,
                normal=np.array([0.0, 0.0, 1.0]),
                area=1.0,
                outline=[square],
                free_area=0.6,
                disc_center=np.array([0.5, 0.5]),
                disc_radius=0.25,
                safe=True,
            ),
            SupportSurface(
                id=5, height=0.9, normal=np.array([0.0, 0.0, 1.0]), area=2.0, outline=[square]
            ),
        ],
    )


@pytest.fixture
def pub():
    with Publisher("tcp://127.0.0.1:*", "surfaces") as p:
        yield p


def test_echo_text_blocks(pub):
    cli = Cli("echo", "surfaces", "--endpoint", pub.endpoint, "--count", "3")
    cli.publish_until(lambda i: pub.publish(surfaces_msg(i)), lambda: False)
    assert cli.finish() == 0
    text = "\n".join(cli.stdout)
    assert text.count("---") == 3
    assert text.count("type: SupportSurfaces") == 3
    assert "frame_id: map" in text
    assert re.search(r"id 3  height 0\.420 m  area 1\.000 m2  free disc r 0\.250 m", text)
    assert "safe yes" in text
    assert "id 5  height 0.900 m" in text and "free disc n/a" in text
    assert cli.stderr == []


def test_echo_json_pointcloud():
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (500, 3)).astype(np.float32)
    intensity = rng.uniform(0, 1, 500).astype(np.float32)
    with Publisher("tcp://127.0.0.1:*", "scan") as pub:
        cli = Cli("echo", "scan", "--endpoint", pub.endpoint, "--json", "--count", "2")
        cli.publish_until(
            lambda i: pub.publish_cloud(
                points, frame_id="lidar", fields={"intensity": intensity}, gravity=(0, 0, -9.81)
            ),
            lambda: False,
        )
        assert cli.finish() == 0
    lines = [json.loads(line) for line in cli.stdout]
    assert len(lines) == 2
    for obj in lines:
        assert obj["type"] == "PointCloud" and obj["topic"] == "scan"
        assert obj["frame_id"] == "lidar" and obj["count"] == 500
        assert obj["fields"]["x"] == {"dtype": "float32", "shape": [500]}
        assert obj["fields"]["intensity"] == {"dtype": "float32", "shape": [500]}
        assert obj["gravity"] == [0.0, 0.0, -9.81]
        assert obj["bytes"] > 500 * 16
    assert lines[1]["seq"] > lines[0]["seq"] >= 1


def test_echo_malformed_one_stderr_line_and_continues(pub):
    cli = Cli("echo", "surfaces", "--endpoint", pub.endpoint, "--json", "--count", "3")
    # Connected once the first message is printed; then exactly one malformed message.
    cli.publish_until(lambda i: pub.publish(surfaces_msg(i)), lambda: len(cli.stdout) >= 1)
    pub._pub.send([b"surfaces", b"\xc1not msgpack"])
    cli.publish_until(lambda i: pub.publish(surfaces_msg(100 + i)), lambda: False)
    assert cli.finish() == 0
    assert len(cli.stderr) == 1, cli.stderr
    assert "surfaces" in cli.stderr[0] and "skipped" in cli.stderr[0]
    objs = [json.loads(line) for line in cli.stdout]
    assert len(objs) == 3
    assert [s["id"] for s in objs[-1]["surfaces"]] == [3, 5]
    assert objs[-1]["surfaces"][0]["height"] == pytest.approx(0.42)
    assert objs[-1]["surfaces"][1]["disc_radius"] is None  # NaN is not JSON
    assert objs[-1]["seq"] >= 100


def test_hz_rate_close_to_published(pub):
    rate = 25.0
    cli = Cli("hz", "surfaces", "--endpoint", pub.endpoint, "--window", "20", "--duration", "4")
    start = time.monotonic()
    i = 0
    while cli.proc.poll() is None and time.monotonic() - start < 10.0:
        pub.publish(surfaces_msg(i))
        i += 1
        # Paced against the clock, so a late wake-up does not lower the rate.
        time.sleep(max(0.0, start + i / rate - time.monotonic()))
    assert cli.finish() == 0
    rates = [float(m[1]) for line in cli.stdout if (m := re.match(r"rate ([\d.]+) Hz", line))]
    assert rates, cli.stdout
    assert rates[-1] == pytest.approx(rate, rel=0.3)
    last = next(line for line in reversed(cli.stdout) if line.startswith("rate"))
    assert re.search(r"period min [\d.]+ s  max [\d.]+ s  std [\d.]+ s  window 20", last)
    assert "MB/s" in last
    assert any(line.startswith("total ") for line in cli.stderr)
