"""Node benchmarks: stage latency, end-to-end latency over sockets, cost as the map grows,
drops and memory at twice the input rate, accuracy and id switches on simulated sequences.

    python bench/bench_node.py [--scene kitchen] [--frames 30] [--lidar os128|vlp16]
                               [--only stages,e2e,standing,growth,rate,ids]
                               [--map-points recent] [--in-process] [--set KEY=VALUE ...]
                               [--runs 3] [--docs] [--soak MIN]

Prints one JSON object per part. The lidar is the simulator's os128 (128 x 1024 = 131,072
rays; a scan holds as many points as rays hit something).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import multiprocessing as mp
import os
import socket
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np

import supportnode
from supportnode.client import (
    ObstacleClusters,
    Publisher,
    Subscriber,
    SupportSurfaces,
    pose_from_matrix,
)
from supportnode.config import load_config
from supportnode.errors import SupportNodeError
from supportnode.map import VoxelMap
from supportnode.msgs import PointCloud
from supportnode.node.allocator import retain_freed_memory
from supportnode.node.node import Node
from supportnode.params import DetectParams
from supportnode.sim import Lidar, load_scene, parse_scene, poses_for
from supportnode.sim.noise import NoiseSpec
from supportnode.sim.scene import scene_path
from supportnode.sim.simulate import scans

warnings.filterwarnings("ignore", category=RuntimeWarning)

# --set KEY=VALUE overrides (the node's configuration for every part), and the parameters
# they give; set by main.
SETS: list[str] = []
PARAMS = DetectParams()
# The source tree of the supportnode this script imported: `supportnode run` is started from
# it, so that a benchmark run with PYTHONPATH=<a worktree> measures that worktree's node (with
# `python -m`, the working directory comes first on the path).
SOURCE = os.path.dirname(os.path.dirname(os.path.abspath(supportnode.__file__)))


# The kitchen with a front wall and a ceiling: every ray of the os128 hits, 131,072 points a scan.
_CLOSE = """
  - {kind: box, name: wall_front, size: [5.2, 0.1, 2.5], xyz: [0, -2.05, 1.25], role: structure}
  - {kind: box, name: ceiling, size: [5.2, 4.2, 0.05], xyz: [0, 0, 2.525], role: structure}
"""


def scene_by_name(name: str):
    """A bundled scene, or ``kitchen_closed`` (the kitchen closed on all sides)."""
    if name == "kitchen_closed":
        text = scene_path("kitchen").read_text(encoding="utf-8") + _CLOSE
        return parse_scene(text, name="kitchen_closed")
    return load_scene(name)


def moving_maps(n_scans: int, scene_name: str = "kitchen_closed"):
    """The node's map (default parameters) after each of ``n_scans`` moving OS-128 scans along
    the scene's path, noise-free: yields (scan index, VoxelMap), the same map object updated."""
    scene = scene_by_name(scene_name)
    m = VoxelMap(DetectParams().node.map)
    sc = scans(scene, Lidar.preset("os128"), poses_for(scene, n_scans), seed=0, frame="sensor")
    for i, s in enumerate(sc):
        m.integrate(s.points, s.sensor_pose, 0.1 * i)
        yield i, m


def _cloud(s, stamp: float, seq: int) -> PointCloud:
    return PointCloud.from_xyz(
        s.points, stamp, "lidar", seq=seq, pose=pose_from_matrix(s.sensor_pose)
    )


def _pct(x) -> dict:
    a = np.asarray(x, float) * 1e3
    return {
        "p50_ms": round(float(np.percentile(a, 50)), 1),
        "p99_ms": round(float(np.percentile(a, 99)), 1),
    }


def stages(sc) -> dict:
    """In-process: per-stage latency over the sequence (the first 3 scans warm up)."""
    with Node(PARAMS) as node:
        rows = [node.process(_cloud(s, 0.1 * i, i + 1)).timings for i, s in enumerate(sc)][3:]
    keys = rows[0].keys()
    return {
        "points": int(np.mean([len(s) for s in sc])),
        "stages": {k: _pct([r.get(k, 0.0) for r in rows]) for k in keys},
    }


def growth(sc, factor: int = 10) -> dict:
    """Latency with the map the sequence builds, and with factor x as many voxels put in
    first: up to 40 parallel walls 10 m long and 2.5 m high, 8 to 18 m away (inside the map
    radius, apart from the scene). The first scans (full detection) are left out."""
    out = {}
    for extra in (False, True):
        with Node(PARAMS) as node:
            if extra:
                target = factor * _base_voxels(sc)
                rng = np.random.default_rng(0)
                y, z = np.meshgrid(np.arange(-5, 5, 0.02), np.arange(0, 2.5, 0.02))
                k = 0
                while node.map.stats()["voxels"] < target and k < 40:
                    # 1 cm thick: a wall of exactly collinear footprint makes objects.py's
                    # oriented box allocate K x K (reported)
                    x = 8.0 + 0.25 * k + rng.uniform(0, 0.01, y.size)
                    wall = np.c_[x, y.ravel(), z.ravel()]
                    # seen from straight above the wall: its rays cross no other wall
                    above = np.eye(4)
                    above[:3, 3] = (8.0 + 0.25 * k, 0.0, 20.0)
                    node.map.integrate(wall, above, 0.0, in_map_frame=True)
                    k += 1
            t = [
                node.process(_cloud(s, 0.1 * i, i + 1)).timings["total"] for i, s in enumerate(sc)
            ][3:]
            out["extra" if extra else "base"] = {"voxels": node.map.stats()["voxels"], **_pct(t)}
    out["ratio_p50"] = round(out["extra"]["p50_ms"] / out["base"]["p50_ms"], 2)
    return out


def _base_voxels(sc) -> int:
    from supportnode.map import VoxelMap

    m = VoxelMap(PARAMS.node.map)
    for i, s in enumerate(sc):
        m.integrate(s.points, s.sensor_pose, 0.1 * i)
    return len(m)


def _wait_ready(sub, timeout: float = 180.0) -> None:
    """Until the node's diagnostics say it is ready (kernels compiled or loaded, subscribed:
    a fresh source tree compiles them first), then one second for the subscriptions (ZeroMQ's
    slow joiner). A node without the ``ready`` gauge: its first diagnostics."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        msg = sub.recv(0.5)
        if msg is not None and hasattr(msg, "gauges") and msg.gauges.get("ready", 1.0) == 1.0:
            break
    time.sleep(1.0)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _drive(sc, endpoint: str, rate: float, go, total: int | None = None) -> None:
    """A lidar driver in its own process: publishes the scans at ``rate`` Hz, each stamped
    with the wall clock when it is sent (the subscriber measures against it: the same clock
    in every process of the machine); ``total`` scans (the sequence over and over), default
    the sequence once."""
    pub = Publisher(endpoint, "scan", hwm=2)
    clouds = [_cloud(s, 0.0, 0) for s in sc]  # the poses; stamps and seqs are set per send
    go.wait()
    t0 = time.monotonic()
    for i in range(total or len(clouds)):
        c = clouds[i % len(clouds)]
        pub.publish(dataclasses.replace(c, stamp=time.time(), seq=i + 1))
        time.sleep(max(t0 + (i + 1) / rate - time.monotonic(), 0.0))
    time.sleep(1.0)
    pub.close()


def e2e(sc, rate: float, slow_consumer: float = 0.0, in_process: bool = False) -> dict:
    """Over sockets on 127.0.0.1: the scans published at ``rate`` Hz, latency from publish
    to the SupportSurfaces received (matched by stamp), drops, and the node's largest memory
    in each third of the run.

    As deployed: the node is ``supportnode run`` in its own process, the publisher (a
    driver) in another, the planner (this process) in a third. ``in_process``: the node in a
    thread of this process instead, beside the publisher: they share one interpreter lock,
    which adds their encoding and decoding to the node's stages."""
    if in_process:
        return _e2e_in_process(sc, rate, slow_consumer)
    parts = 3
    scan_ep, pub_ep = (f"tcp://127.0.0.1:{_free_port()}" for _ in range(2))
    ctx = mp.get_context("fork")
    go = ctx.Event()
    driver = ctx.Process(target=_drive, args=(sc, scan_ep, rate, go), daemon=True)
    driver.start()
    sets = [
        *SETS,
        f"node.scan_endpoint={scan_ep}",
        f"node.pub_endpoint={pub_ep}",
        "node.diagnostics_period=0.5",
    ]
    path = os.pathsep.join(p for p in (SOURCE, os.environ.get("PYTHONPATH")) if p)
    node = subprocess.Popen(
        [sys.executable, "-m", "supportnode", "run", "--log-level", "WARNING"]
        + [a for kv in sets for a in ("--set", kv)],
        cwd=SOURCE,
        env={**os.environ, "PYTHONPATH": path},
    )
    sub = Subscriber(["surfaces", "obstacles", "diagnostics"], pub_ep, keep_newest=100)
    lat: list[tuple[float, float]] = []
    lat_o: list[float] = []
    diags = []
    try:
        _wait_ready(sub)
        go.set()
        t0 = time.monotonic()
        span = len(sc) / rate
        while time.monotonic() < t0 + span + 2.0:
            msg = sub.recv(0.1)
            if isinstance(msg, SupportSurfaces):
                lat.append((msg.stamp, time.time() - msg.stamp))
                if slow_consumer:
                    time.sleep(slow_consumer)
            elif isinstance(msg, ObstacleClusters):
                lat_o.append(time.time() - msg.stamp)
            elif msg is not None:
                diags.append((time.monotonic() - t0, msg))
    finally:
        node.terminate()
        node.wait(10)
        driver.join(10)
        sub.close()
    last = diags[-1][1]
    part = span / parts
    rss = [
        max(
            (d.gauges["rss_mb"] for t, d in diags if k * part <= t < (k + 1) * part),
            default=float("nan"),
        )
        for k in range(parts)
    ]
    out = _e2e_summary(rate, len(sc), last, lat, rss, "process")
    out["obstacles_latency"] = _pct(lat_o) if lat_o else None
    out["_samples"] = {"surfaces": [x for _, x in lat], "obstacles": lat_o}
    return out


# Latencies of scans published this long after the first one are the steady state: the
# first detections run on a cold map, memo and worker.
WARMUP_S = 1.0


def _e2e_summary(rate, sent, d, lat, rss, mode) -> dict:
    """lat: (publication time, latency) of each SupportSurfaces received, seconds."""
    c = d.counters
    first = min((t for t, _ in lat), default=0.0)
    steady = [x for t, x in lat if t - first >= WARMUP_S]
    lat = [x for _, x in lat]
    return {
        "node": mode,
        "rate_hz": rate,
        "scans_sent": sent,
        "received": c["scans_received"],
        "processed": c["scans_processed"],
        "dropped": c["scans_dropped"],
        "detections": c["detections"],
        "detections_reused": c.get("detections_reused", 0),
        "detections_skipped": c.get("detections_skipped", 0),
        "obstacles_skipped": c.get("obstacles_skipped", 0),
        "surfaces_received": len(lat),
        "latency": _pct(lat) if lat else None,
        f"latency_after_{WARMUP_S:g}s": _pct(steady) if steady else None,
        "node_stages": {
            k: {"p50_ms": round(v.p50 * 1e3, 1), "p99_ms": round(v.p99 * 1e3, 1)}
            for k, v in d.latencies.items()
        },
        "rss_mb_per_pass": [round(x, 1) for x in rss],
    }


def _e2e_in_process(sc, rate: float, slow_consumer: float = 0.0) -> dict:
    from dataclasses import replace

    pub = Publisher("tcp://127.0.0.1:*", "scan", hwm=2)
    p = PARAMS
    p = replace(
        p,
        node=replace(
            p.node,
            scan_endpoint=pub.endpoint,
            pub_endpoint="tcp://127.0.0.1:*",
            diagnostics_period=0.5,
        ),
    )
    node = Node(p)
    node.open()
    th = threading.Thread(target=node.spin, kwargs={"handle_signals": False}, daemon=True)
    th.start()
    sub = Subscriber("surfaces", node.pub_endpoint, keep_newest=100)
    time.sleep(0.5)
    sent: dict[float, float] = {}
    lat = []
    n = len(sc)
    rss = []
    t0 = time.monotonic()
    for i, s in enumerate(sc):
        stamp = 0.1 * i
        sent[round(stamp, 6)] = time.perf_counter()
        pub.publish(_cloud(s, stamp, i + 1))
        next_t = t0 + (i + 1) / rate
        while (left := next_t - time.monotonic()) > 0:
            msg = sub.recv(left)
            if isinstance(msg, SupportSurfaces):
                lat.append((msg.stamp, time.perf_counter() - sent[round(msg.stamp, 6)]))
                if slow_consumer:
                    time.sleep(slow_consumer)
        if (3 * (i + 1)) % n < 3:  # the end of each third
            rss.append(node.diagnostics().gauges["rss_mb"])
    time.sleep(1.0)
    d = node.diagnostics()
    node.stop()
    th.join(5)
    node.close()
    pub.close()
    sub.close()
    return _e2e_summary(rate, n, d, lat, rss, "thread")


def soak(sc, minutes: float, rate: float) -> dict:
    """``supportnode run`` fed the moving sequence over and over at ``rate`` Hz for
    ``minutes``: its resident memory (diagnostics' rss_mb) after the first minute and at the
    end, and the growth between them (target: < 5 %)."""
    scan_ep, pub_ep = (f"tcp://127.0.0.1:{_free_port()}" for _ in range(2))
    ctx = mp.get_context("fork")
    go = ctx.Event()
    total = int(minutes * 60 * rate)
    driver = ctx.Process(target=_drive, args=(sc, scan_ep, rate, go, total), daemon=True)
    driver.start()
    sets = [*SETS, f"node.scan_endpoint={scan_ep}", f"node.pub_endpoint={pub_ep}"]
    path = os.pathsep.join(p for p in (SOURCE, os.environ.get("PYTHONPATH")) if p)
    node = subprocess.Popen(
        [sys.executable, "-m", "supportnode", "run", "--log-level", "WARNING"]
        + [a for kv in sets for a in ("--set", kv)],
        cwd=SOURCE,
        env={**os.environ, "PYTHONPATH": path},
    )
    sub = Subscriber("diagnostics", pub_ep, keep_newest=10)
    rss: list[tuple[float, float]] = []
    last = None
    try:
        _wait_ready(sub)
        go.set()
        t0 = time.monotonic()
        while time.monotonic() < t0 + total / rate + 2.0:
            msg = sub.recv(0.5)
            if msg is not None:
                rss.append((time.monotonic() - t0, msg.gauges["rss_mb"]))
                last = msg
    finally:
        node.terminate()
        node.wait(10)
        driver.join(10)
        sub.close()
    first = [r for t, r in rss if 60.0 <= t < 70.0] or [rss[0][1]]
    end = [r for _, r in rss[-10:]]
    c = last.counters if last is not None else {}
    return {
        "minutes": minutes,
        "rate_hz": rate,
        "scans_sent": total,
        "processed": c.get("scans_processed"),
        "detections": c.get("detections"),
        "rss_mb_after_1min": round(float(np.median(first)), 1),
        "rss_mb_end": round(float(np.median(end)), 1),
        "rss_growth_pct": round(float(100 * (np.median(end) / np.median(first) - 1)), 2),
    }


def _pooled(runs: list[dict]) -> dict:
    """p50/p99 over the scans of all e2e runs, and each run's detected count."""
    s = [x for r in runs for x in r["_samples"]["surfaces"]]
    o = [x for r in runs for x in r["_samples"]["obstacles"]]
    return {
        "runs": len(runs),
        "surfaces": _pct(s) if s else None,
        "obstacles": _pct(o) if o else None,
        "detected": [r["surfaces_received"] for r in runs],
        "skipped": [r["detections_skipped"] for r in runs],
        "obstacles_skipped": [r.get("obstacles_skipped", 0) for r in runs],
        "sent": runs[0]["scans_sent"],
    }


_STAGE_ROWS = (
    ("merge (map)", "map"),
    ("map points", "points"),
    ("clearing (after the surfaces)", "clear"),
    ("surfaces", "surfaces"),
    ("objects", "objects"),
    ("free space", "free_space"),
    ("ids (tracking)", "track"),
    ("messages", "messages"),
    ("scan -> results, in process", "total"),
)


def docs_text(st: dict, pooled: dict, noise: float) -> str:
    """The docs block: in-process stages, then end to end over sockets against the targets."""
    from common import table

    rows = [
        [label, f"{st['stages'][k]['p50_ms']:.1f}", f"{st['stages'][k]['p99_ms']:.1f}"]
        for label, k in _STAGE_ROWS
        if k in st["stages"]
    ]
    out = [f"stages, in process ({st['points']:,} points a scan), ms", ""]
    out.append(table(rows, ["stage", "p50", "p99"]))
    tgt = ("70", "140") if noise > 0 else ("50", "100")
    s, o = pooled["surfaces"] or {}, pooled["obstacles"] or {}
    sent = pooled["sent"]
    e2e_rows = [
        ["surfaces p50, ms", f"{s.get('p50_ms', float('nan')):.1f}", f"<= {tgt[0]}"],
        ["surfaces p99, ms", f"{s.get('p99_ms', float('nan')):.1f}", f"<= {tgt[1]}"],
        ["obstacles p50, ms", f"{o.get('p50_ms', float('nan')):.1f}", "" if noise else "<= 80"],
        [
            "scans detected per run",
            " ".join(f"{d}/{sent}" for d in pooled["detected"]),
            f">= {int(0.95 * sent)}/{sent}",
        ],
        ["skipped for a newer scan", " ".join(map(str, pooled["skipped"])), "rare"],
        [
            "obstacles skipped for a newer scan",
            " ".join(map(str, pooled["obstacles_skipped"])),
            "",
        ],
    ]
    head = f"end to end over sockets, `supportnode run` in its own process, {pooled['runs']} runs"
    if noise > 0:
        head += f", {noise * 100:g} cm gaussian noise"
    out += ["", head, "", table(e2e_rows, ["what", "measured", "target"])]
    return "\n".join(out)


def ids(scene_name: str, frames: int, map_points: str = "stable") -> dict:
    """Accuracy and id switches on a simulated sequence. A ground-truth surface is found when
    a published surface lies within 3 cm of its height and 1 m of its centre (the largest such
    one counts); a ground-truth object when a published cluster's centroid is within 10 cm of
    its centroid in x, y and in z (z too: on a shelf, objects on different boards share x, y).
    An id switch: the id found for one ground-truth item changes between two scans where it is
    found. Then the same poses are scanned again: on that static second pass, how many new
    obstacle ids appear per scan (any cluster: what a planner sees appear). ``map_points``: the
    map's representation (stable, recent)."""
    scene = scene_by_name(scene_name)
    sc = scans(scene, Lidar.preset("os128"), poses_for(scene, frames), seed=0, frame="sensor")
    gt_s: dict[int, list[np.ndarray]] = {}
    gt_o: dict[int, list[np.ndarray]] = {}
    for s in sc:
        w = s.points.astype(np.float64) @ s.sensor_pose[:3, :3].T + s.sensor_pose[:3, 3]
        for sid in np.unique(s.surface[s.surface >= 0]):
            gt_s.setdefault(int(sid), []).append(w[s.surface == sid])
        for oid in np.unique(s.object[s.object >= 0]):
            gt_o.setdefault(int(oid), []).append(w[s.object == oid])
    sh = {k: float(np.median(np.concatenate(v)[:, 2])) for k, v in gt_s.items()}
    sc_ = {k: np.concatenate(v)[:, :2].mean(axis=0) for k, v in gt_s.items()}
    oc = {k: np.concatenate(v).mean(axis=0) for k, v in gt_o.items()}
    s_ids: dict[int, list[int]] = {k: [] for k in gt_s}
    o_ids: dict[int, list[int]] = {k: [] for k in gt_o}
    s_found, o_found = [], []
    with Node(
        PARAMS, map_factory=lambda: VoxelMap(PARAMS.node.map, representation=map_points)
    ) as node:
        for i, s in enumerate(sc):
            out = node.process(_cloud(s, 0.1 * i, i + 1))
            hits = 0
            for k in gt_s:
                best = [
                    x
                    for x in out.surfaces.surfaces
                    if abs(x.height - sh[k]) < 0.03
                    and np.all(np.abs(np.concatenate(x.outline).mean(axis=0) - sc_[k]) < 1.0)
                ]
                if best:
                    s_ids[k].append(max(best, key=lambda x: x.area).id)
                    hits += 1
            s_found.append(hits / max(len(gt_s), 1))
            hits = 0
            for k in gt_o:
                near = [
                    c
                    for c in out.obstacles.clusters
                    if np.linalg.norm(c.centroid[:2] - oc[k][:2]) < 0.10
                    and abs(c.centroid[2] - oc[k][2]) < 0.10
                ]
                if near:
                    o_ids[k].append(max(near, key=lambda c: c.point_count).id)
                    hits += 1
            o_found.append(hits / max(len(gt_o), 1))
        new_ids = [
            len(node.process(_cloud(s, 0.1 * (frames + i), frames + i + 1)).new_ids["obstacles"])
            for i, s in enumerate(sc)
        ]

    def switches(d: dict[int, list[int]]) -> int:
        return sum(int(np.sum(np.diff(v) != 0)) for v in d.values() if len(v) > 1)

    return {
        "scene": scene_name,
        "frames": frames,
        "gt_surfaces": len(gt_s),
        "surface_recall_last": round(s_found[-1], 3),
        "surface_recall_mean": round(float(np.mean(s_found)), 3),
        "surface_id_switches": switches(s_ids),
        "gt_objects": len(gt_o),
        "object_recall_last": round(o_found[-1], 3),
        "object_recall_mean": round(float(np.mean(o_found)), 3),
        "object_id_switches": switches(o_ids),
        "map_points": map_points,
        "new_obstacle_ids_per_scan_second_pass": round(float(np.mean(new_ids)), 2),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="kitchen_closed")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--lidar", default="os128", help="simulated lidar preset (os128, vlp16)")
    ap.add_argument(
        "--noise",
        type=float,
        default=0.0,
        help="gaussian noise of the scans, m (stages, e2e, standing, growth, rate; default none)",
    )
    ap.add_argument("--only", default="stages,e2e,standing,growth,rate,ids")
    ap.add_argument(
        "--in-process",
        action="store_true",
        help="e2e: the node in a thread of the benchmark (beside the publisher), not its own process",
    )
    ap.add_argument(
        "--map-points",
        default="stable",
        choices=("stable", "recent"),
        help="ids: the map's representation",
    )
    ap.add_argument(
        "--default-malloc",
        action="store_true",
        help="leave glibc's allocator as it is (supportnode run keeps freed memory)",
    )
    ap.add_argument("--runs", type=int, default=1, help="e2e: runs, pooled into one p50/p99")
    ap.add_argument(
        "--docs",
        action="store_true",
        help="write the stage and end-to-end table into docs/performance.md (runs stages, e2e)",
    )
    ap.add_argument(
        "--soak",
        type=float,
        default=0.0,
        metavar="MIN",
        help="also run the node MIN minutes at 20 Hz and report its memory growth",
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="configuration override for the node in every part, as for supportnode run",
    )
    args = ap.parse_args()
    global PARAMS
    try:
        PARAMS = load_config(None, args.set)
    except SupportNodeError as err:
        ap.error(str(err))
    SETS[:] = args.set
    if not (np.isfinite(args.noise) and args.noise >= 0):
        ap.error(f"--noise: expected a finite number >= 0, got {args.noise}")
    if not args.default_malloc:
        retain_freed_memory()  # as `supportnode run` does
    parts = {p for p in args.only.split(",") if p} | ({"stages", "e2e"} if args.docs else set())
    load0 = os.getloadavg()
    unknown = parts - {"stages", "e2e", "standing", "growth", "rate", "ids"}
    if unknown:
        ap.error(f"--only: unknown part(s) {', '.join(sorted(unknown))}")
    scene = scene_by_name(args.scene)
    lidar = Lidar.preset(args.lidar)
    noise = NoiseSpec(gauss=args.noise)
    sc = scans(scene, lidar, poses_for(scene, args.frames), seed=0, noise=noise, frame="sensor")
    st = None
    if "stages" in parts:
        st = stages(sc)
        print(json.dumps({"stages": st}), flush=True)
    if parts & {"e2e", "rate"} or args.soak > 0:
        # Moving: three times the poses along the same path, every scan a new view.
        poses = poses_for(scene, 3 * args.frames)
        moving = scans(scene, lidar, poses, seed=0, noise=noise, frame="sensor")
    if "e2e" in parts:
        runs = []
        for _ in range(max(args.runs, 1)):
            res = e2e(moving, 10.0, in_process=args.in_process)
            runs.append(res)
            print(json.dumps({"e2e_10hz": {k: v for k, v in res.items() if k != "_samples"}}))
        pooled = _pooled(runs)
        print(json.dumps({"e2e_10hz_pooled": pooled}), flush=True)
        if args.docs and st is not None:
            from common import docs_command, host_load, write_docs_block

            path = Path(SOURCE) / "docs" / "performance.md"
            text = docs_text(st, pooled, args.noise)
            cmd = docs_command("bench_node.py", sys.argv[1:])
            block = "bench_node.noise" if args.noise > 0 else "bench_node"
            write_docs_block(path, block, text, cmd, host_load(load0))
            print(f"wrote {path}", file=sys.stderr)
    if "standing" in parts:
        # A robot standing before the scene (one pose of the sequence), a new scan each time:
        # with a noise-free sensor the map stops changing once its voxels are full.
        pose = poses_for(scene, args.frames)[args.frames // 2]
        poses = np.repeat(pose[None], 3 * args.frames, 0)
        still = scans(scene, lidar, poses, noise=noise, frame="sensor")
        res = e2e(still, 10.0, in_process=args.in_process)
        res.pop("_samples", None)
        print(json.dumps({"e2e_10hz_standing": res}), flush=True)
    if "rate" in parts:
        res = e2e(moving, 20.0, slow_consumer=0.05, in_process=args.in_process)
        res.pop("_samples", None)
        print(json.dumps({"e2e_20hz_slow_consumer": res}), flush=True)
    if args.soak > 0:
        print(json.dumps({"soak": soak(moving, args.soak, 20.0)}), flush=True)
    if "growth" in parts:
        print(json.dumps({"growth": growth(sc)}), flush=True)
    if "ids" in parts:
        for name in ("table_chairs", "kitchen", "shelf"):
            print(json.dumps({"ids": ids(name, args.frames, args.map_points)}), flush=True)


if __name__ == "__main__":
    main()
