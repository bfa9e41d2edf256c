"""Benchmark of the node's voxel map: integrate time, growth with map size, detection through the
map against the raw scan, and id switches of the trackers on simulated lidar sequences.

    python3 bench/bench_map.py            # everything (a few minutes on one core)
    python3 bench/bench_map.py --only time,growth,accuracy,ids
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import table

from supportnode.map import VoxelMap
from supportnode.node.tracking import ClusterTracker, SurfaceTracker
from supportnode.params import MapParams

REPO = Path(__file__).resolve().parents[1]

# A closed room, so that every one of the os128's 131,072 rays returns a point.
ROOM = """
name: bench_room
primitives:
  - {kind: box, name: floor, size: [24, 12, 0.02], xyz: [0, 0, -0.01], role: surface, surface: floor}
  - {kind: box, name: ceiling, size: [24, 12, 0.02], xyz: [0, 0, 3.01], role: structure}
  - {kind: box, name: wall_n, size: [24, 0.1, 3], xyz: [0, 6.05, 1.5], role: structure}
  - {kind: box, name: wall_s, size: [24, 0.1, 3], xyz: [0, -6.05, 1.5], role: structure}
  - {kind: box, name: wall_e, size: [0.1, 12, 3], xyz: [12.05, 0, 1.5], role: structure}
  - {kind: box, name: wall_w, size: [0.1, 12, 3], xyz: [-12.05, 0, 1.5], role: structure}
  - {kind: box, name: table_a, size: [1.6, 0.9, 0.04], xyz: [-4, 2, 0.73], role: surface, surface: table_a}
  - {kind: box, name: table_b, size: [1.2, 1.2, 0.04], xyz: [3, -2, 0.73], role: surface, surface: table_b}
  - {kind: box, name: shelf, size: [2.0, 0.4, 0.02], xyz: [6, 5.5, 1.0], role: surface, surface: shelf}
  - {kind: box, name: crate, size: [0.5, 0.4, 0.4], xyz: [-4, 2, 0.95], role: object, object: crate}
  - {kind: box, name: cabinet, size: [0.6, 0.6, 1.2], xyz: [0, 4, 0.6], role: object, object: cabinet}
  - {kind: cylinder, name: pillar, radius: 0.3, height: 3, xyz: [1, -1, 1.5], role: structure}
"""


def room_scans(n: int, seed: int = 0):
    """n os128 scans (131,072 points each) along a line through the room, 0.1 s apart."""
    from supportnode.sim import Lidar, parse_scene
    from supportnode.sim.noise import parse_noise
    from supportnode.sim.scene import pose_matrix
    from supportnode.sim.simulate import finish

    scene = parse_scene(ROOM)
    lidar = Lidar.preset("os128")
    noise = parse_noise(["range:0.01"])
    out = []
    for i in range(n):
        pose = pose_matrix([-8.0 + 0.15 * i, -0.5 + 0.02 * i, 1.2], [0, 0, 2.0 * i])
        cloud = lidar.scan(scene, pose, stamp=0.1 * i)
        out.append(finish(cloud, scene, noise, np.random.default_rng([seed, i]), "world"))
    return out


def bench_time(clouds, clear: bool) -> list[object]:
    m = VoxelMap(MapParams(clear_free_space=clear))
    times = []
    for c in clouds:
        t = time.perf_counter()
        m.integrate(c.points, c.sensor_pose, c.stamp, in_map_frame=True)
        times.append(time.perf_counter() - t)
    return [
        "on" if clear else "off",
        len(clouds),
        int(np.mean([len(c) for c in clouds])),
        1e3 * statistics.median(times),
        1e3 * max(times),
        len(m),
    ]


def _filler(n_voxels: int, rng) -> np.ndarray:
    """Points filling about n_voxels 5 cm voxels outside the room (x > 13 m), no clearing ray
    reaches them; 2 points per voxel."""
    side = int(np.ceil(np.sqrt(n_voxels / 8)))
    g = np.stack(np.meshgrid(np.arange(side), np.arange(side), np.arange(8), indexing="ij"), -1)
    centres = (g.reshape(-1, 3) + 0.5) * 0.05 + [13.0, -side * 0.025, 0.0]
    centres = centres[:n_voxels]
    return np.repeat(centres, 2, axis=0) + rng.uniform(-0.02, 0.02, (2 * len(centres), 3))


def bench_growth(clouds) -> list[list[object]]:
    """Per-scan cost with the map at 1x and 10x voxels (same scans, filler outside the room)."""
    rng = np.random.default_rng(1)
    rows = []
    base = None
    warm, timed = clouds[:10], clouds[10:]
    for factor in (1, 10):
        m = VoxelMap(MapParams(radius=100.0, max_voxels=50_000_000))
        for c in warm:
            m.integrate(c.points, c.sensor_pose, c.stamp, in_map_frame=True)
        n1 = len(m) if base is None else base
        base = n1
        if factor > 1:
            fill = _filler((factor - 1) * n1, rng)
            m.integrate(fill, warm[-1].sensor_pose, warm[-1].stamp, in_map_frame=True)
        size = len(m)
        t_int, t_pts, t_all = [], [], []
        for c in timed:
            t = time.perf_counter()
            touched = m.integrate(c.points, c.sensor_pose, c.stamp, in_map_frame=True)
            t_int.append(time.perf_counter() - t)
            t = time.perf_counter()
            m.points(touched.keys)
            t_pts.append(time.perf_counter() - t)
        t = time.perf_counter()
        m.points()
        t_all.append(time.perf_counter() - t)
        rows.append(
            [
                f"{factor}x",
                size,
                1e3 * statistics.median(t_int),
                1e3 * statistics.median(t_pts),
                1e3 * statistics.median(np.add(t_int, t_pts)),
                1e3 * max(t_int),
                1e3 * t_all[0],
            ]
        )
    ratio = rows[1][4] / rows[0][4]
    rows.append(["ratio", rows[1][1] / rows[0][1], "", "", ratio, "", rows[1][6] / rows[0][6]])
    return rows


def _sequence(name: str, frames: int | None):
    """Clouds of a simulated sequence: the committed 5-frame files, or `frames` new ones."""
    from supportnode.sim import Lidar, load_scene, poses_for
    from supportnode.sim.files import read_sim_npz
    from supportnode.sim.simulate import scans

    if frames is None:
        folder = REPO / "sim_scans" / f"{name}_lidar"
        return [read_sim_npz(p) for p in sorted(folder.glob("frame_*.npz"))]
    scene = load_scene(name)
    return scans(scene, Lidar.preset("os128"), poses_for(scene, frames), seed=0)


def _transfer(src_pts: np.ndarray, src_labels: np.ndarray, dst: np.ndarray, radius: float):
    """Labels of dst points from their nearest src point within radius (-1 beyond)."""
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(src_pts).query(dst, distance_upper_bound=radius)
    ok = np.isfinite(dist)
    out = np.full(len(dst), -1, np.int64)
    out[ok] = src_labels[idx[ok]]
    return out


def bench_accuracy(seqs: dict) -> list[list[object]]:
    """Surface scores on each frame's raw points: detection on that scan alone, on all scans so
    far concatenated, and through the map (labels carried from map points to scan points)."""
    from supportnode.pipeline import detect
    from supportnode.sim.evaluate import evaluate

    rows = []
    for name, clouds in seqs.items():
        acc: dict[str, list] = {}
        maps = {
            r: VoxelMap(MapParams(), representation=r) for r in ("stable", "recent", "centroid")
        }
        for i, c in enumerate(clouds):
            pts = c.points.astype(np.float64)
            origin = c.sensor_pose[:3, 3]
            variants = {"raw scan": pts, "raw, all scans so far": None}
            allp = np.concatenate([x.points for x in clouds[: i + 1]]).astype(np.float64)
            variants["raw, all scans so far"] = allp
            for r, m in maps.items():
                m.integrate(pts, c.sensor_pose, c.stamp, in_map_frame=True)
                variants[f"map ({r})"] = m.points()
            for label, p in variants.items():
                det = detect(p, objects=True, sensor_origin=origin)
                ps = det.surfaces.labels.astype(np.int64)
                po = det.objects.labels.astype(np.int64)
                if p is not pts:
                    ps = _transfer(p, ps, pts, 0.05)
                    po = _transfer(p, po, pts, 0.05)
                ev = evaluate(ps, po, c.surface, c.object)
                s, o = ev["surfaces"], ev["objects"]
                acc.setdefault(label, []).append(
                    (s["precision"], s["recall"], s["found"], s["gt_count"], o["ari"], len(p))
                )
        for label, vals in acc.items():
            v = np.array(vals, dtype=np.float64)
            rows.append(
                [
                    name,
                    label,
                    v[:, 0].mean(),
                    v[:, 1].mean(),
                    f"{int(v[:, 2].sum())}/{int(v[:, 3].sum())}",
                    v[:, 4].mean(),
                    int(v[:, 5].mean()),
                ]
            )
    return rows


def _majority(pred: np.ndarray, gt: np.ndarray, n_pred: int) -> np.ndarray:
    """GT id holding the majority (>= 50 %) of each predicted label's points, -1 otherwise."""
    out = np.full(n_pred, -1, np.int64)
    for k in range(n_pred):  # a handful of detections per scan
        g = gt[pred == k]
        g = g[g >= 0]
        if len(g):
            vals, cnt = np.unique(g, return_counts=True)
            if cnt.max() >= 0.5 * (pred == k).sum():
                out[k] = vals[np.argmax(cnt)]
    return out


def _switches(history: list[dict[int, int]]) -> tuple[int, int]:
    """ID switches (a GT object's track id differs from the one it had when last matched) and
    the number of GT matches, over frames of {gt id: track id}."""
    last: dict[int, int] = {}
    sw = total = 0
    for frame in history:
        for g, tid in frame.items():
            total += 1
            if g in last and last[g] != tid:
                sw += 1
            last[g] = tid
    return sw, total


def bench_ids(seqs: dict) -> list[list[object]]:
    from supportnode.pipeline import detect

    rows = []
    for name, clouds in seqs.items():
        m = VoxelMap(MapParams())
        st, ct = SurfaceTracker(), ClusterTracker()
        surf_hist, obj_hist = [], []
        new_s = new_o = 0
        for c in clouds:
            pts = c.points.astype(np.float64)
            m.integrate(pts, c.sensor_pose, c.stamp, in_map_frame=True)
            mp = m.points()
            det = detect(mp, objects=True, sensor_origin=c.sensor_pose[:3, 3])
            su = st.update_surfaces(det.surfaces.surfaces)
            sid = np.array(
                [-1 if k.surface_id is None else su.ids[k.surface_id] for k in det.objects.clusters]
            )
            cu = ct.update_clusters(det.objects.clusters, sid)
            new_s += len(su.new)
            new_o += len(cu.new)
            ls = _transfer(mp, det.surfaces.labels.astype(np.int64), pts, 0.05)
            lo = _transfer(mp, det.objects.labels.astype(np.int64), pts, 0.05)
            gs = _majority(ls, c.surface, len(su.ids))
            go = _majority(lo, c.object, len(cu.ids))
            # One detection per GT id per frame (the largest, first in order) for the count.
            surf_hist.append(
                {int(g): int(t) for g, t in zip(gs[::-1], su.ids[::-1], strict=True) if g >= 0}
            )
            obj_hist.append(
                {int(g): int(t) for g, t in zip(go[::-1], cu.ids[::-1], strict=True) if g >= 0}
            )
        s_sw, s_n = _switches(surf_hist)
        o_sw, o_n = _switches(obj_hist)
        rows.append([name, len(clouds), s_sw, s_n, new_s, o_sw, o_n, new_o])
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="time,growth,accuracy,ids")
    ap.add_argument("--scans", type=int, default=30, help="room scans for time and growth")
    ap.add_argument("--frames", type=int, default=20, help="frames of the longer sequences")
    args = ap.parse_args(argv)
    parts = set(args.only.split(","))
    if parts & {"time", "growth"}:
        t = time.perf_counter()
        clouds = room_scans(args.scans)
        print(f"simulated {len(clouds)} os128 scans in {time.perf_counter() - t:.1f} s\n")
    if "time" in parts:
        rows = [bench_time(clouds[:20], clear) for clear in (False, True)]
        head = ["clearing", "scans", "points", "median ms", "max ms", "voxels"]
        print("integrate, os128 scans through a room (map: 5 cm, 20 m radius)")
        print(table(rows, head) + "\n")
    if "growth" in parts:
        head = ["map", "voxels", "integrate ms", "points(touched) ms", "sum ms", "max ms"]
        head.append("points() ms")
        print("per-scan cost against map size (median over the scans after 10 warm-up scans)")
        print(table(bench_growth(clouds), head) + "\n")
    if parts & {"accuracy", "ids"}:
        seqs = {f"{n} x5": _sequence(n, None) for n in ("shelf", "table_chairs")}
        if args.frames:
            for n in ("shelf", "table_chairs", "kitchen"):
                seqs[f"{n} x{args.frames}"] = _sequence(n, args.frames)
    if "accuracy" in parts:
        head = ["sequence", "detection on", "surf P", "surf R", "found", "obj ARI", "points"]
        print("surfaces on each frame's points, mean over frames")
        print(table(bench_accuracy(seqs), head) + "\n")
    if "ids" in parts:
        head = ["sequence", "frames", "surf IDSW", "surf matches", "surf ids"]
        head += ["obj IDSW", "obj matches", "obj ids"]
        print("id switches against ground truth, map + detect + trackers")
        print(table(bench_ids(seqs), head))


if __name__ == "__main__":
    main()
