"""`supportnode run --input REC --output results.mcap`: the node offline, deterministic, and
with the same results as a live replay slow enough for the node to keep up."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import run_cli

from supportnode.io.recording import McapFile
from supportnode.msgs import decode_any

REPO = Path(__file__).resolve().parents[2]
RECORDING = REPO / "sim_scans" / "table_chairs_lidar.mcap"  # 5 posed OS-128 scans at 10 Hz


def _results(path: Path) -> dict[tuple[str, float], list[tuple]]:
    """(topic, stamp) -> what a planner reads: surfaces (id, height, area, safe) or obstacles
    (id, surface, point count), rounded."""
    out: dict[tuple[str, float], list[tuple]] = {}
    with McapFile(path) as f:
        for raw in f.messages():
            msg = decode_any(raw.frames())
            key = (raw.channel.topic, round(msg.stamp, 6))
            if raw.channel.topic == "surfaces":
                out[key] = [
                    (s.id, round(s.height, 3), round(s.area, 2), s.safe) for s in msg.surfaces
                ]
            else:
                out[key] = [(c.id, c.surface_id, c.point_count) for c in msg.clusters]
    return out


def test_offline_run_is_deterministic_and_complete(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    first = run_cli("run", "--input", str(RECORDING), "--output", str(a))
    assert first.returncode == 0, first.stderr
    assert "wrote" in first.stdout
    assert run_cli("run", "--input", str(RECORDING), "--output", str(b), "--quiet").returncode == 0
    ra, rb = _results(a), _results(b)
    assert ra == rb
    assert sorted(k[1] for k in ra if k[0] == "surfaces") == pytest.approx([0, 0.1, 0.2, 0.3, 0.4])
    lines = [json.loads(x) for x in a.with_suffix(".jsonl").read_text().splitlines()]
    assert [x["seq"] for x in lines] == [0, 1, 2, 3, 4] and all(x["detected"] for x in lines)
    assert lines[-1]["surfaces"][0]["height"] == pytest.approx(0.0, abs=0.02)


def test_offline_run_bad_input_is_one_line(tmp_path: Path) -> None:
    res = run_cli("run", "--input", str(tmp_path / "nope.mcap"))
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [
        f"supportnode run: error: {tmp_path / 'nope.mcap'}: no such file or folder"
    ]


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.slow
def test_offline_results_equal_a_live_replay_the_node_keeps_up_with(tmp_path: Path) -> None:
    offline = tmp_path / "offline.mcap"
    assert run_cli("run", "--input", str(RECORDING), "--output", str(offline)).returncode == 0
    scan_port, pub_port = _port(), _port()
    scan_ep, pub_ep = f"tcp://127.0.0.1:{scan_port}", f"tcp://127.0.0.1:{pub_port}"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    base = [sys.executable, "-m", "supportnode"]
    node = subprocess.Popen(
        [*base, "run", "--set", f"node.scan_endpoint={scan_ep}", "--set", f"node.pub_endpoint={pub_ep}"],
        cwd=REPO, env=env, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    live = tmp_path / "live.mcap"
    rec = subprocess.Popen(
        [*base, "record", "surfaces", "obstacles", "-o", str(live), "--endpoint", pub_ep, "--quiet"],
        cwd=REPO, env=env, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        # one scan a second: far slower than the node, so no scan is skipped
        play = subprocess.run(
            [*base, "play", str(RECORDING), "--endpoint", scan_ep, "--rate", "0.1", "--wait", "4", "--quiet"],
            cwd=REPO, env=env, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert play.returncode == 0, play.stderr
        time.sleep(2.0)  # the last detection
    finally:
        for proc in (rec, node):
            proc.send_signal(signal.SIGINT)
        for proc in (rec, node):
            proc.wait(timeout=30)
    assert rec.returncode == 0 and node.returncode == 0, node.stderr.read()[-2000:]
    assert _results(live) == _results(offline)
