"""Accuracy on real labelled tabletop scans (the mOSD layout), beside the Open3D pipeline.

Each scan is detected as a user runs `supportnode detect SCAN --align` (aligned from normals,
the sensor at the camera's origin). Per scan and per scene group: table precision/recall
(the detected surface holding most table points against labels 1-9), object ARI over the
ground-truth object points (a segment = one label >= 20; every point the detection gives to
no object shares one "none" label), parts recovered (one cluster holds >= 80 % of the part's
points and >= 80 % of that cluster's points, table included, are the part's), parts merged /
split / lost into the table, refused scans (ARI 0, nothing recovered) and in-process seconds
per scan (the stage timings: gravity, surfaces, objects, free space). Where open3d is
installed, the same run scores the plain Open3D tabletop pipeline (segment_plane 1 cm, points
> 1 cm above, cluster_dbscan eps 2 cm) and a tuned one (table band 1.2 cm, eps 7 mm).

Run: python bench/real_accuracy.py [--scans ../shared/real_scans/mosd_learn] [--every 1]
     [--set objects.method=voxel] [--no-open3d] [--decimate K] [--docs]
(--decimate K keeps every K-th row and column of each organised scan: a coarser camera.)
Its last line is JSON (mean ARI, parts recovered, median s/scan per method): two revisions
by turns with ``bench/ab.py --a REV -- bench/real_accuracy.py --no-open3d``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import docs_command, host_load, table, write_docs_block

REPO = Path(__file__).resolve().parents[1]
GROUPS = ((0, 16, "boxes"), (17, 24, "stacked"), (25, 32, "occluded"), (33, 44, "cylinders"))
RECOVERED = 0.8  # the share of a part in its cluster, and of the cluster in the part


@dataclass
class Score:
    """One method on one scan."""

    ari: float = 0.0
    parts: int = 0
    recovered: int = 0
    merged: int = 0
    split: int = 0
    lost: int = 0
    table_p: float = 0.0
    table_r: float = 0.0
    seconds: float = 0.0
    refused: bool = False
    extra: dict = field(default_factory=dict)


def group_of(name: str) -> str:
    """The mOSD scene group of 'learnN' (learn 0-16 boxes, 17-24 stacked, ...)."""
    m = re.search(r"(\d+)$", name)
    k = int(m.group(1)) if m else -1
    return next((g for lo, hi, g in GROUPS if lo <= k <= hi), "other")


def ari(truth: np.ndarray, pred: np.ndarray) -> float:
    """Adjusted Rand index of two (N,) integer labelings (1.0 for identical partitions)."""
    n = len(truth)
    if n < 2:
        return 1.0
    _, t = np.unique(truth, return_inverse=True)
    _, p = np.unique(pred, return_inverse=True)
    cont = np.bincount(t * (p.max() + 1) + p).astype(np.float64)

    def pairs(x: np.ndarray) -> float:
        return float((x * (x - 1) / 2).sum())

    s_ij = pairs(cont)
    s_a, s_b = pairs(np.bincount(t).astype(float)), pairs(np.bincount(p).astype(float))
    expected = s_a * s_b / (n * (n - 1) / 2)
    top = 0.5 * (s_a + s_b)
    return 1.0 if top == expected else (s_ij - expected) / (top - expected)


def score(labels: np.ndarray, objects: np.ndarray, table_mask: np.ndarray) -> Score:
    """Score a detection. labels: (N,) mOSD labels; objects: (N,) cluster per point, -1 for
    none; table_mask: (N,) bool, the points the detection puts on the table."""
    gt_table = (labels >= 1) & (labels <= 9)
    obj = labels >= 20
    s = Score()
    hit = (table_mask & gt_table).sum()
    s.table_p = float(hit / max(table_mask.sum(), 1))
    s.table_r = float(hit / max(gt_table.sum(), 1))
    s.ari = ari(labels[obj], objects[obj])
    sizes = np.bincount(objects[objects >= 0]) if (objects >= 0).any() else np.zeros(0, int)
    for part in np.unique(labels[obj]):
        s.parts += 1
        mine = labels == part
        lab = objects[mine]
        on = lab[lab >= 0]
        if table_mask[mine].mean() > 0.5:
            s.lost += 1
            continue
        if len(on) == 0:
            s.split += 1
            continue
        best = np.bincount(on).argmax()
        share = (lab == best).sum()
        if share >= RECOVERED * mine.sum() and share >= RECOVERED * sizes[best]:
            s.recovered += 1
        elif share >= RECOVERED * mine.sum():
            s.merged += 1
        else:
            s.split += 1
    return s


def run_ours(points: np.ndarray, labels: np.ndarray, params) -> Score:
    """supportnode detect --align on one camera-frame scan (N, 3), metres."""
    from supportnode.errors import AlignmentError
    from supportnode.pipeline import detect

    try:
        d = detect(points, params, align=True, sensor_origin=np.zeros(3), origin_assumed=True)
    except AlignmentError:
        s = Score(parts=len(np.unique(labels[labels >= 20])), refused=True)
        s.split = s.parts
        return s
    gt_table = (labels >= 1) & (labels <= 9)
    surf = d.surfaces.labels
    on_table = surf[gt_table & (surf >= 0)]
    table_id = np.bincount(on_table).argmax() if len(on_table) else -2
    s = score(labels, d.objects.labels.astype(np.int64), surf == table_id)
    s.seconds = sum(
        v for k, v in d.timings.items() if k in ("gravity", "surfaces", "objects", "free_space")
    )
    return s


def run_open3d(
    points: np.ndarray, labels: np.ndarray, band: float, eps: float, table_band: float | None
) -> Score:
    """The Open3D tabletop pipeline: RANSAC plane, points above it, DBSCAN."""
    import open3d as o3d

    o3d.utility.random.seed(0)
    t = time.perf_counter()
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    plane, inliers = pc.segment_plane(distance_threshold=0.01, ransac_n=3, num_iterations=1000)
    n = np.asarray(plane, dtype=np.float64)
    if n[3] < 0:  # the camera (the origin) on the positive side: "above" is toward it
        n = -n
    dist = points @ n[:3] + n[3]
    above = np.flatnonzero(dist > band)
    objects = np.full(len(points), -1, np.int64)
    if len(above):
        sub = pc.select_by_index(above.tolist())
        objects[above] = np.asarray(sub.cluster_dbscan(eps=eps, min_points=10))
    seconds = time.perf_counter() - t
    table_mask = np.zeros(len(points), bool)
    if table_band is None:
        table_mask[np.asarray(inliers)] = True
    else:
        table_mask = np.abs(dist) <= table_band
    s = score(labels, objects, table_mask)
    s.seconds = seconds
    return s


def summarise(scores: list[Score]) -> list[object]:
    """Mean ARI, parts recovered/merged/split/lost, refusals, worst table P/R, median s."""
    parts = sum(s.parts for s in scores)
    rec = sum(s.recovered for s in scores)
    return [
        float(np.mean([s.ari for s in scores])),
        f"{rec}/{parts}",
        sum(s.merged for s in scores),
        sum(s.split for s in scores),
        sum(s.lost for s in scores),
        sum(s.refused for s in scores),
        float(min(s.table_p for s in scores)),
        float(min(s.table_r for s in scores)),
        float(np.median([s.seconds for s in scores])),
    ]


HEADER = [
    "group",
    "method",
    "ARI",
    "parts",
    "merged",
    "split",
    "lost",
    "refused",
    "min P",
    "min R",
    "s/scan",
]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scans", type=Path, default=REPO.parent / "shared/real_scans/mosd_learn")
    ap.add_argument("--every", type=int, default=1, help="score every k-th scan only")
    ap.add_argument("--set", action="append", default=[], help="config override key=value")
    ap.add_argument("--no-open3d", action="store_true")
    ap.add_argument(
        "--decimate",
        type=int,
        default=1,
        help="keep every k-th row and column of each scan (k = 2: a 320 x 240 camera)",
    )
    ap.add_argument("--per-scan", action="store_true", help="print a row per scan")
    ap.add_argument("--docs", action="store_true", help="write the table into docs/accuracy.md")
    args = ap.parse_args(argv)
    if args.every < 1 or args.decimate < 1:
        ap.error(f"--every and --decimate must be at least 1, got {args.every}, {args.decimate}")
    from supportnode.config import load_config
    from supportnode.io.clouds import read_cloud
    from supportnode.kernels import runtime

    load0 = os.getloadavg()
    params = load_config(None, args.set)
    runtime.warm()
    runtime.keep_freed_memory()  # as `supportnode detect` runs
    try:
        import open3d  # noqa: F401

        peers = not args.no_open3d
    except ImportError:
        peers = False
    files = sorted(args.scans.glob("*.pcd"), key=lambda p: int(re.sub(r"\D", "", p.stem) or 0))
    files = files[:: args.every]
    if not files:
        print(f"real_accuracy: no .pcd scans in {args.scans}", file=sys.stderr)
        return 2
    methods = {"supportnode": []} | ({"open3d plain": [], "open3d tuned": []} if peers else {})
    groups: list[str] = []
    per_scan = []
    for path in files:
        cloud = read_cloud(path)
        pts, lab = cloud.points, cloud.fields["label"].astype(np.int64)
        if args.decimate > 1 and cloud.width:
            row_of, col_of = np.divmod(cloud.source_index, cloud.width)
            keep = (row_of % args.decimate == 0) & (col_of % args.decimate == 0)
            pts, lab = pts[keep], lab[keep]
        groups.append(group_of(path.stem))
        row = [path.stem]
        for name in methods:
            if name == "supportnode":
                s = run_ours(pts, lab, params)
            elif name == "open3d plain":
                s = run_open3d(pts, lab, 0.01, 0.02, None)
            else:
                s = run_open3d(pts, lab, 0.012, 0.007, 0.012)
            methods[name].append(s)
            row += [s.ari, f"{s.recovered}/{s.parts}", s.table_p, s.table_r, s.seconds]
        per_scan.append(row)
        if args.per_scan:
            print(*(f"{v:.3f}" if isinstance(v, float) else v for v in row), sep="  ", flush=True)
    rows = []
    for g in [*dict.fromkeys(groups), "all"]:
        for name, scores in methods.items():
            pick = [s for s, gg in zip(scores, groups, strict=True) if g in ("all", gg)]
            rows.append([g, name, *summarise(pick)])
    text = table(rows, HEADER)
    if peers:
        ours = np.median([s.seconds for s in methods["supportnode"]])
        plain = np.median([s.seconds for s in methods["open3d plain"]])
        text += f"\nsupportnode is {plain / ours:.1f}x faster than plain Open3D (median s/scan)"
    load = host_load(load0)
    print(text)
    print(f"host load {load}")
    # One JSON line for bench/ab.py (revisions compared by turns): medians over all scans.
    summary = {
        name: {
            "ari": float(np.mean([s.ari for s in scores])),
            "recovered": int(sum(s.recovered for s in scores)),
            "s_per_scan": float(np.median([s.seconds for s in scores])),
        }
        for name, scores in methods.items()
    }
    print(json.dumps({"real_accuracy": summary}), flush=True)
    if args.docs:
        cmd = docs_command("real_accuracy.py", argv)
        # A coarser camera's table beside the full one, not over it.
        block = "real_accuracy" + (f".decimate{args.decimate}" if args.decimate > 1 else "")
        write_docs_block(REPO / "docs/accuracy.md", block, text, cmd, load)
    return 0


if __name__ == "__main__":
    sys.exit(main())
