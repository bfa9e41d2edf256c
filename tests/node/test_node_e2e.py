"""`supportnode run` as a subprocess over real sockets on 127.0.0.1: simulated scans in,
surfaces and obstacles out; garbage, a restarting publisher, a late subscriber; SIGTERM."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
import zmq
from conftest import REPO

from supportnode.client import (
    Diagnostics,
    ObstacleClusters,
    PointCloud,
    Publisher,
    Subscriber,
    SupportSurfaces,
)
from supportnode.sim import Lidar, load_scene, poses_for
from supportnode.sim.simulate import scans


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def sim_scans():
    scene = load_scene("table_chairs")
    return scans(scene, Lidar.preset("os128"), poses_for(scene, 40)[:8], seed=0, frame="sensor")


def _start(scan_port: int, pub_port: int) -> subprocess.Popen:
    cmd = [
        sys.executable, "-m", "supportnode", "run",
        "--set", f"node.scan_endpoint=tcp://127.0.0.1:{scan_port}",
        "--set", f"node.pub_endpoint=tcp://127.0.0.1:{pub_port}",
        "--set", "node.diagnostics_period=0.3",
        "--set", "node.map_period=0.3",
        "--set", "node.reject_log_period=5",
    ]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen(cmd, cwd=REPO, env=env, stderr=subprocess.PIPE, text=True)


def _send(pub: Publisher, s, stamp: float) -> None:
    pub.publish_cloud(s.points, stamp=stamp, frame_id="lidar", pose=s.sensor_pose)


def test_run_end_to_end(sim_scans):
    ctx = zmq.Context()
    scan_port, pub_port = _free_port(), _free_port()
    proc = _start(scan_port, pub_port)
    started = time.monotonic()
    try:
        pub = Publisher(f"tcp://127.0.0.1:{scan_port}", "scan", context=ctx)
        sub = Subscriber(
            ["surfaces", "obstacles", "diagnostics", "map"], f"tcp://127.0.0.1:{pub_port}",
            context=ctx, keep_newest=5,
        )  # fmt: skip
        raw = pub._pub  # garbage goes out on the same socket, as a broken driver would send it
        surfaces: list[SupportSurfaces] = []
        obstacles: list[ObstacleClusters] = []
        diags: list[Diagnostics] = []
        maps: list[PointCloud] = []
        deadline = time.monotonic() + 40
        i = 0
        while time.monotonic() < deadline and len(surfaces) < 5:
            _send(pub, sim_scans[i % len(sim_scans)], 100.0 + 0.1 * i)
            raw.send([b"scan", b"\xc1 not msgpack"])
            raw.send([b"scan"])
            i += 1
            t_end = time.monotonic() + 0.4
            while (msg := sub.recv(max(0.0, t_end - time.monotonic()))) is not None:
                {
                    SupportSurfaces: surfaces,
                    ObstacleClusters: obstacles,
                    Diagnostics: diags,
                    PointCloud: maps,
                }[type(msg)].append(msg)
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        assert len(surfaces) >= 5
        last = surfaces[-1]
        heights = sorted(round(s.height, 2) for s in last.surfaces)
        assert 0.0 in heights and 0.75 in [round(h, 2) for h in heights]
        table = next(s for s in last.surfaces if abs(s.height - 0.75) < 0.03)
        box = [c for c in obstacles[-1].clusters if c.surface_id == table.id]
        assert box, "the box on the table"
        assert any(np.linalg.norm(c.centroid[:2] - [0.2, 0.05]) < 0.1 for c in box)
        # the map, one point per voxel in the results' frame: floor and table top in it
        assert maps and maps[-1].frame_id == last.frame_id and maps[-1].count > 1000
        z = maps[-1].points[:, 2]
        assert (np.abs(z) < 0.03).sum() > 500 and (np.abs(z - 0.75) < 0.03).sum() > 100
        # stable ids: the table keeps its id over the run
        table_ids = {s.id for m in surfaces[1:] for s in m.surfaces if abs(s.height - 0.75) < 0.03}
        assert len(table_ids) == 1

        # the publisher restarts (stamps start over); a late subscriber joins
        pub.close()
        time.sleep(0.2)
        pub = Publisher(f"tcp://127.0.0.1:{scan_port}", "scan", context=ctx)
        late = Subscriber("surfaces", f"tcp://127.0.0.1:{pub_port}", context=ctx)
        got = None
        deadline = time.monotonic() + 20
        j = 0
        while got is None and time.monotonic() < deadline:
            _send(pub, sim_scans[j % len(sim_scans)], 0.1 * j)
            j += 1
            got = late.recv(0.5)
        assert isinstance(got, SupportSurfaces)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            msg = sub.recv(0.5)
            if isinstance(msg, Diagnostics):
                diags.append(msg)
                c = msg.counters
                # the restart seen, and the detection of its scan finished (its surfaces went
                # out first): a new timeline is admitted a second after the old one stopped
                if c.get("time_jumps", 0) >= 1 and c["detections"] >= c["scans_processed"]:
                    break
        d = diags[-1]
        # garbage that arrives while a scan is processed may be dropped as older than the
        # newest message (keep-newest), so not all of it reaches the decoder
        assert d.counters["rejected_malformed"] >= 2
        assert d.counters["scans_processed"] >= 5
        assert d.counters["time_jumps"] >= 1
        assert {"map", "surfaces", "total"} <= set(d.latencies)
        assert d.gauges["map_voxels"] > 0
        assert d.gauges["ready"] == 1.0  # kernels warmed before subscribing

        # SIGTERM: gone within 2 s, exit code 0
        t = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
        assert time.monotonic() - t < 2.0
        err = proc.stderr.read() if proc.stderr else ""
        # one line per reject period (5 s), not one per bad message
        periods = 1 + int((time.monotonic() - started) / 5.0)
        assert 1 <= err.count("rejected a scan") <= periods + 1
        # the closing summary counts from the socket at the end, not the last diagnostics
        import re

        m = re.search(r"stopped: (\d+) scans received, (\d+) processed.*?(\d+) detections", err)
        assert m, err[-500:]
        received, processed, detections = map(int, m.groups())
        assert received >= processed >= detections > 0
        # the kernels were ready before the node subscribed (said once, before "scans from"),
        # and the wait for them was announced first (a fresh install compiles for seconds)
        assert err.count("kernels ready in") == 1
        assert err.index("preparing kernels") < err.index("kernels ready in"), err[:500]
        assert err.index("kernels ready in") < err.index("scans from"), err[:500]
        for s in (pub, sub, late):
            s.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        ctx.destroy(linger=0)


def test_sigint_before_any_scan_exits_cleanly():
    proc = _start(_free_port(), _free_port())
    try:
        # Spinning (its start is logged), not merely started: a SIGINT during the imports is
        # Ctrl-C before the node runs (exit code 130), and imports take seconds on a loaded host.
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line or "scans from" in line:
                break
        assert "scans from" in line, "the node did not log its start"
        t = time.monotonic()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=5) == 0
        assert time.monotonic() - t < 2.0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
