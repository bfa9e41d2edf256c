"""Hostile drivers against `supportnode run` over 127.0.0.1: hostile messages interleaved with
good scans (each sent once the node is free), an overload at a multiple of the detection rate,
driver restarts.

    python bench/bench_hostile.py [--hostile 10000] [--overload 60] [--factor 2.5]
                                  [--restarts 6] [--frames 20] [--docs]

The node is ``supportnode run`` in its own process (this tree's, default configuration but
node.max_points 200,000 and node.max_message_bytes 4 MiB, so that the too-many-points and
oversized messages stay small); good scans are the simulator's moving OS-128 scans of the
closed kitchen (131,072 points), stamped with the wall clock when sent, so latency is the time
from sending to the SupportSurfaces received. Hostile messages cycle through
`supportnode.msgs.hostile.rejects` (every reject reason). Prints a table; ``--docs`` also
writes it into docs/robustness.md (between its bench_hostile markers), with the command and
the host's load.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_node import SOURCE, _cloud, _free_port, scene_by_name

from supportnode.bus import CurveKeys, publisher_when_free
from supportnode.client import Diagnostics, Subscriber, SupportSurfaces
from supportnode.msgs import Limits, PointCloud
from supportnode.msgs.hostile import rejects
from supportnode.sim import Lidar, poses_for
from supportnode.sim.simulate import scans

MAX_POINTS, MAX_BYTES = 200_000, 4 << 20
DOCS = Path(__file__).resolve().parent.parent / "docs" / "robustness.md"
BEGIN, END = "<!-- bench_hostile: begin -->", "<!-- bench_hostile: end -->"


class Node:
    """``supportnode run`` as a subprocess, its driver socket and a results subscriber."""

    def __init__(self) -> None:
        self.scan_ep = f"tcp://127.0.0.1:{_free_port()}"
        pub_ep = f"tcp://127.0.0.1:{_free_port()}"
        sets = [
            f"node.scan_endpoint={self.scan_ep}",
            f"node.pub_endpoint={pub_ep}",
            "node.diagnostics_period=0.5",
            f"node.max_points={MAX_POINTS}",
            f"node.max_message_bytes={MAX_BYTES}",
        ]
        self.log = tempfile.TemporaryFile("w+")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "supportnode", "run", *[a for s in sets for a in ("--set", s)]],
            cwd=SOURCE,
            env={**os.environ, "PYTHONPATH": SOURCE},
            stderr=self.log,
        )
        self.pub = publisher_when_free(self.scan_ep, hwm=1000)
        self.sub = Subscriber(["surfaces", "diagnostics"], pub_ep, keep_newest=1000)
        self.results: dict[float, float] = {}  # stamp -> latency, s
        self.diagnostics: list[tuple[float, Diagnostics]] = []

    def pump(self, seconds: float) -> None:
        """Take the node's messages for ``seconds``."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            msg = self.sub.recv(min(left, 0.05))
            if isinstance(msg, SupportSurfaces):
                self.results[msg.stamp] = time.time() - msg.stamp
            elif isinstance(msg, Diagnostics):
                self.diagnostics.append((time.monotonic(), msg))

    def fresh(self) -> Diagnostics:
        n = len(self.diagnostics)
        while len(self.diagnostics) == n:
            self.pump(0.1)
            if self.proc.poll() is not None:
                raise SystemExit("bench_hostile.py: the node ended")
        return self.diagnostics[-1][1]

    def stop(self) -> str:
        self.pub.close()
        self.sub.close()
        self.proc.terminate()
        self.proc.wait(10)
        self.log.seek(0)
        return self.log.read()


def rss(d: Diagnostics) -> float:
    """The node's memory with its detection worker's, MiB."""
    return d.gauges.get("rss_mb", 0.0) + d.gauges.get("rss_mb_worker", 0.0)


def pct(values, q: float) -> float:
    return float(np.percentile(np.asarray(values) * 1e3, q)) if len(values) else float("nan")


def scan(clouds, i: int, stamp: float, rng: np.random.Generator) -> list:
    """The frames of scan ``i`` (cycling), stamped, with 5 mm of noise: a new scan each time,
    so the map changes and no detection is reused."""
    c = clouds[i % len(clouds)]
    pts = c.points + rng.normal(0.0, 0.005, (c.count, 3))
    return PointCloud.from_xyz(
        pts.astype(np.float32), stamp, c.frame_id, i + 1, pose=c.pose
    ).encode("scan")


def hostile_run(node: Node, clouds, count: int, per_scan: int, rng: np.random.Generator) -> dict:
    """``count`` hostile messages, ``per_scan`` after each good scan (every reason in turn);
    the next good scan once the last one has its result (or after 5 s): the node is free."""
    limits = Limits(max_points=MAX_POINTS, max_message_bytes=MAX_BYTES)
    catalogue = [
        (reason, frames)
        for reason, messages in rejects(clouds[0].points, time.time(), limits).items()
        for frames in messages
    ]
    goods = max(1, count // per_scan)
    per_good = count / goods
    sent: collections.Counter[str] = collections.Counter()
    good_stamps = []
    for i in range(max(10, len(clouds))):  # warm-up: the map of the whole path, the worker
        stamp = time.time()
        node.pub.send(scan(clouds, i, stamp, rng))
        deadline = time.monotonic() + 10.0
        while stamp not in node.results and time.monotonic() < deadline:
            node.pump(0.01)
    before = node.fresh()
    t0, k, half = time.monotonic(), 0, None
    for i in range(goods):
        if i == goods // 2:
            half = node.fresh()
        stamp = time.time()
        node.pub.send(scan(clouds, i, stamp, rng))
        good_stamps.append(stamp)
        while k < round((i + 1) * per_good):
            reason, frames = catalogue[k % len(catalogue)]
            if reason == "stamp_jump":
                frames = dataclasses.replace(clouds[0], stamp=stamp + 1e9).encode("scan")
            node.pub.send(frames)
            sent[reason] += 1
            k += 1
        deadline = time.monotonic() + 5.0
        while stamp not in node.results and time.monotonic() < deadline:
            node.pump(0.01)
    node.pump(2.0)
    after = node.fresh()
    c = after.counters
    got = [node.results[s] for s in good_stamps if s in node.results]
    return {
        "sent": sent,
        "goods": goods,
        "counters": c,
        "results": len(got),
        "latency": got,
        "rss": (rss(before), rss(half or before), rss(after)),
        "seconds": time.monotonic() - t0,
    }


def overload(node: Node, clouds, seconds: float, factor: float, rng: np.random.Generator) -> dict:
    """Good scans at ``factor`` times the detection rate (1 / the node's median detection
    time so far, its diagnostics' ``detect`` stage) for ``seconds``; the node's memory sampled
    from its diagnostics."""
    start = node.fresh()
    detect_s = start.latencies["detect"].p50
    rate = factor / detect_s
    c0, n0 = start.counters, len(node.diagnostics)
    stamps, t0 = [], time.monotonic()
    while time.monotonic() - t0 < seconds:
        stamp = time.time()
        node.pub.send(scan(clouds, len(stamps), stamp, rng))
        stamps.append(stamp)
        node.pump(max(0.0, t0 + len(stamps) / rate - time.monotonic()))
    node.pump(2.0)
    end = node.fresh()
    mem = [rss(d) for _, d in node.diagnostics[n0:]]
    got = [node.results[s] for s in stamps if s in node.results]
    c = {k: end.counters[k] - c0.get(k, 0) for k in end.counters if k in c0}
    return {
        "detect_s": detect_s,
        "rate": rate,
        "sent": len(stamps),
        "results": len(got),
        "latency": got,
        "counters": c,
        "rss": (mem[0], max(mem), mem[-1]),
    }


def restarts(node: Node, clouds, count: int, rng: np.random.Generator) -> dict:
    """The driver restarts ``count`` times; every other time a driver with the wrong security
    mechanism (CURVE) holds the endpoint for a second first, and every third restart starts
    its stamps over (a replay started again). Time from the new driver's bind to a result."""
    import zmq.auth

    keys = Path(tempfile.mkdtemp())
    zmq.auth.create_certificates(keys, "driver")
    curve = CurveKeys(keys / "driver.key_secret", authorized_dir=keys)
    back = 0.0
    times = []
    for r in range(count):
        node.pub.close()
        if r % 2:
            with publisher_when_free(node.scan_ep, curve=curve, hwm=1000) as wrong:
                for _ in range(10):
                    wrong.send(clouds[0].encode("scan"))
                    time.sleep(0.1)
        if r % 3 == 2:
            back += 3600.0  # stamps an hour back: the source started over
        node.pub = publisher_when_free(node.scan_ep, hwm=1000)
        t = time.monotonic()
        while True:
            stamp = time.time() - back
            node.pub.send(scan(clouds, r, stamp, rng))
            node.pump(0.1)
            if stamp in node.results or any(s < stamp and s > stamp - 0.5 for s in node.results):
                break
            if time.monotonic() - t > 30:
                raise SystemExit("bench_hostile.py: the driver was not heard after a restart")
        times.append(time.monotonic() - t)
    return {"times": times, "counters": node.fresh().counters}


def report(h: dict, o: dict, r: dict, log: str) -> str:
    c = h["counters"]
    rows = [
        ("hostile messages sent", f"{sum(h['sent'].values()):,}"),
        ("good scans sent / got results", f"{h['goods']:,} / {h['results']:,}"),
        ("  not detected: dropped for a newer scan / skipped while busy",
         f"{c['scans_dropped']:,} / {c['detections_skipped']:,}"),
        ("scans received by the node", f"{c['scans_received']:,}"),
        ("rejected (all reasons)", f"{c['scans_rejected']:,}"),
    ]  # fmt: skip
    for reason, n in sorted(h["sent"].items()):
        counted = c.get(f"rejected_{reason}", 0)
        rows.append((f"  {reason}: sent / counted", f"{n:,} / {counted:,}"))
    rows += [
        ("map resets (time_jumps)", f"{c['time_jumps']}"),
        ("latency of good scans p50 / p99, ms", f"{pct(h['latency'], 50):.0f} / {pct(h['latency'], 99):.0f}"),
        ("RSS after a warm-up lap / half way / at the end, MiB (node + worker)", "{:.0f} / {:.0f} / {:.0f}".format(*h["rss"])),
        (f"overload: {o['rate']:.1f} Hz for {o['sent'] / o['rate']:.0f} s "
         f"(detection p50 {o['detect_s'] * 1e3:.0f} ms)", f"{o['sent']:,} scans sent"),
        ("  results / dropped / skipped",
         f"{o['results']:,} / {o['counters']['scans_dropped']:,} / {o['counters']['detections_skipped']:,}"),
        ("  latency p50 / p99, ms", f"{pct(o['latency'], 50):.0f} / {pct(o['latency'], 99):.0f}"),
        ("  RSS first / max / last, MiB", "{:.0f} / {:.0f} / {:.0f}".format(*o["rss"])),
        (f"driver restarts ({len(r['times'])}, half after a wrong-mechanism driver)",
         f"first result after {np.median(r['times']):.2f} s median, {max(r['times']):.2f} s max"),
        ("  handshake failures counted, map resets",
         f"{sum(v for k, v in r['counters'].items() if k.startswith('handshake_failures'))}, "
         f"{r['counters']['time_jumps']}"),
        ("tracebacks in the node's log", str(log.count("Traceback"))),
        ("log lines about rejects", str(log.count("rejected a scan"))),
    ]  # fmt: skip
    width = max(len(a) for a, _ in rows)
    return "\n".join(f"{a.ljust(width)}  {b}" for a, b in rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hostile", type=int, default=10_000, help="hostile messages (10000)")
    ap.add_argument("--per-scan", type=int, default=40, help="hostile messages per good scan")
    ap.add_argument("--overload", type=float, default=60.0, help="overload seconds (60)")
    ap.add_argument("--factor", type=float, default=2.5, help="overload x detection rate")
    ap.add_argument("--restarts", type=int, default=6, help="driver restarts (6)")
    ap.add_argument("--frames", type=int, default=20, help="distinct simulated scans (20)")
    ap.add_argument("--docs", action="store_true", help="write the table into " + str(DOCS))
    args = ap.parse_args()
    for name in ("hostile", "per_scan", "restarts", "frames"):
        if getattr(args, name) < 1:
            flag = name.replace("_", "-")
            ap.error(f"--{flag}: expected an integer >= 1, got {getattr(args, name)}")
    if not (np.isfinite(args.overload) and args.overload > 0 and args.factor > 0):
        ap.error("--overload and --factor: expected numbers > 0")
    scene = scene_by_name("kitchen_closed")
    sim = scans(scene, Lidar.preset("os128"), poses_for(scene, args.frames), seed=0, frame="sensor")
    clouds = [_cloud(s, 0.0, i + 1) for i, s in enumerate(sim)]
    load = os.getloadavg()
    node = Node()
    try:
        node.fresh()
        node.pump(3.0)  # the detection worker's imports
        rng = np.random.default_rng(0)
        h = hostile_run(node, clouds, args.hostile, args.per_scan, rng)
        o = overload(node, clouds, args.overload, args.factor, rng)
        r = restarts(node, clouds, args.restarts, rng)
    finally:
        log = node.stop()
    text = report(h, o, r, log)
    load = f"{load[0]:.1f} (1 min) at the start, {os.getloadavg()[0]:.1f} at the end"
    print(text)
    print(f"host load average: {load}")
    if args.docs:
        command = "python bench/bench_hostile.py" + " ".join(
            f" {a}" for a in sys.argv[1:] if a != "--docs"
        )
        block = f"{BEGIN}\n`{command.strip()}` (host load {load}):\n\n```\n{text}\n```\n{END}"
        doc = DOCS.read_text(encoding="utf-8")
        DOCS.write_text(re.sub(f"{re.escape(BEGIN)}.*?{re.escape(END)}", lambda _: block, doc, flags=re.S), encoding="utf-8")  # fmt: skip
        print(f"wrote {DOCS}")


if __name__ == "__main__":
    main()
