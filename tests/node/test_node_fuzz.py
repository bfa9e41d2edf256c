"""Fuzz `supportnode run` as a subprocess over 127.0.0.1: every reject reason, issue 21's six
faults, a peer with the wrong security mechanism, random header flips. Good scans after them
still get results, every message is counted under exactly one reason, the log holds no
traceback, and the process is alive until SIGTERM ends it cleanly."""

from __future__ import annotations

import collections
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import zmq
from conftest import REPO, free_port
from test_node_hostile import frames, scene

from supportnode.bus import CurveKeys, publisher_when_free
from supportnode.client import Diagnostics, Subscriber, SupportSurfaces
from supportnode.msgs import Limits
from supportnode.msgs.hostile import flipped, rejects

MAX_POINTS, MAX_BYTES = 20_000, 1_000_000


class Results:
    def __init__(self, sub: Subscriber) -> None:
        self.sub = sub
        self.stamps: set[float] = set()
        self.diagnostics: list[Diagnostics] = []

    def pump(self, until, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not until() and time.monotonic() < deadline:
            msg = self.sub.recv(0.05)
            if isinstance(msg, SupportSurfaces):
                self.stamps.add(msg.stamp)
            elif isinstance(msg, Diagnostics):
                self.diagnostics.append(msg)
        return bool(until())

    def result(self, stamp: float) -> bool:
        return self.pump(lambda: stamp in self.stamps, 20.0)

    def fresh(self) -> Diagnostics:
        n = len(self.diagnostics)
        assert self.pump(lambda: len(self.diagnostics) > n, 10.0), "no diagnostics"
        return self.diagnostics[-1]


@pytest.mark.skipif(not zmq.has("curve"), reason="libzmq without CURVE")
def test_fuzz_the_node_subprocess(tmp_path):
    import zmq.auth

    scan_ep = f"tcp://127.0.0.1:{free_port()}"
    pub_ep = f"tcp://127.0.0.1:{free_port()}"
    cmd = [
        sys.executable, "-m", "supportnode", "run",
        "--set", f"node.scan_endpoint={scan_ep}", "--set", f"node.pub_endpoint={pub_ep}",
        "--set", "node.diagnostics_period=0.2", "--set", "node.map_period=0.5",
        "--set", f"node.max_points={MAX_POINTS}", "--set", f"node.max_message_bytes={MAX_BYTES}",
    ]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stderr=subprocess.PIPE, text=True)
    started = time.monotonic()
    pts = scene()
    limits = Limits(max_points=MAX_POINTS, max_message_bytes=MAX_BYTES)
    sent: collections.Counter[str] = collections.Counter()
    pub = publisher_when_free(scan_ep, hwm=1000)
    sub = Subscriber(["surfaces", "diagnostics"], pub_ep, keep_newest=200)
    try:
        res = Results(sub)
        res.fresh()  # the node is up and we are subscribed
        stamp, seq = 100.0, 0

        def good(**kw) -> float:
            nonlocal stamp, seq
            stamp, seq = stamp + 0.1, seq + 1
            pub.send(frames(pts, stamp, kw.pop("seq", seq), **kw))
            return stamp

        assert res.result(good())
        # every reject reason, each after a good scan that must still get its result
        for reason, messages in rejects(pts, stamp, limits).items():
            for bad in messages:
                s = good()
                pub.send(bad)
                sent[reason] += 1
                assert res.result(s), f"the good scan before a {reason} message lost its result"
        # the six faults: any uint64 seq, a sideways gravity, then scans that must be fine
        assert res.result(good(seq=2**64 - 1)) and res.result(good(seq=7))
        assert res.result(good(gravity=[9.8, 0.0, 0.0]))
        assert res.result(good())
        d = res.fresh()
        c = d.counters
        for reason, n in sent.items():
            assert c.get(f"rejected_{reason}", 0) == n, (reason, c)
        assert c["scans_rejected"] == sum(sent.values())
        assert c["gravity_outliers"] == 1 and c["seq_restarts"] >= 2
        assert c["time_jumps"] == 0 and c["diagnostics_failures"] == 0

        # a driver with the wrong security mechanism binds the endpoint, then the real one
        pub.close()
        zmq.auth.create_certificates(tmp_path, "driver")
        curve = CurveKeys(tmp_path / "driver.key_secret", authorized_dir=tmp_path)
        with publisher_when_free(scan_ep, curve=curve, hwm=1000) as wrong:
            deadline = time.monotonic() + 15
            while "handshake_failures_scans_mechanism" not in res.fresh().counters:
                assert time.monotonic() < deadline, "the node never met the wrong driver"
                wrong.send(frames(pts, stamp + 0.05))
        pub = publisher_when_free(scan_ep, hwm=1000)
        deadline = time.monotonic() + 20
        while True:  # a new scan each time, until one gets its result
            sent_at = good()
            if res.pump(lambda s=sent_at: s in res.stamps, 0.3):
                break
            assert time.monotonic() < deadline, "the real driver was not heard again"

        # random header flips: each counted under one reason, or taken as a scan
        for bad in flipped(frames(pts, stamp + 0.05), np.random.default_rng(7), 150):
            pub.send(bad)
        time.sleep(0.5)
        good()
        # a second scan confirms the timeline if a flip moved it
        assert res.result(good()), res.fresh().counters
        c = res.fresh().counters
        assert (
            c["scans_received"] == c["scans_processed"] + c["scans_rejected"] + c["scans_dropped"]
        ), c
        assert proc.poll() is None, "the node ended"
    finally:
        pub.close()
        sub.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=10)
        err = proc.stderr.read() if proc.stderr else ""
    assert code == 0, err[-2000:]
    assert "Traceback" not in err, err[-3000:]
    periods = 1 + int((time.monotonic() - started) / 5.0)
    assert err.count("rejected a scan") <= periods + 1, err[-2000:]
    assert re.search(r"handshake with tcp://127\.0\.0\.1:\d+ failed: security mechanism", err)
