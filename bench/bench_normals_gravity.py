"""Timing of k-NN normals and gravity alignment, beside the report's figure.

    python3 bench/bench_normals_gravity.py [--repeat 5] [--real ../shared/real_scans] [--docs]

Normals: k=30 on a 108,025-point cloud (the report's "table with 2 chairs" size): the simulator's
`table_chairs` scene when available, else a synthetic room. Gravity: 100k and 300k points of
the synthetic room tilted by 30/20 deg, and the simulator scenes tilted, and (when present)
the real camera scans, with the up found per file. Medians of --repeat runs. Where ``open3d`` is
installed (the ``bench`` extra), its ``estimate_normals`` (k=30, all cores) runs on the same cloud
in the same run, our time as a ratio of it. ``--docs`` writes the table into docs/performance.md.
"""

from __future__ import annotations

import argparse
import glob
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

# The test suite's scene builders (tests/geometry/test_gravity.py imports tests/camera_views).
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "geometry"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import docs_command, host_load, write_docs_block
from test_gravity import angle_deg, room, rpy

from supportnode.geometry.gravity import apply_rotation, estimate_gravity
from supportnode.geometry.normals import estimate_normals
from supportnode.params import GravityParams

REPORT_NORMALS_S = 160.41  # k=30 on 108,025 points (AMD Ryzen 5 3600, Python 3.8)
DOCS = Path(__file__).resolve().parents[1] / "docs" / "performance.md"


def open3d_normals(pts: np.ndarray, repeat: int) -> float | None:
    """Median seconds of Open3D's k=30 ``estimate_normals`` on ``pts``, None without open3d."""
    try:
        import open3d as o3d
    except ImportError:
        return None
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    knn = o3d.geometry.KDTreeSearchParamKNN(30)
    cloud.estimate_normals(knn)  # warm-up
    return median_time(lambda: cloud.estimate_normals(knn), repeat)


def median_time(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def cloud_108k() -> tuple[np.ndarray, str]:
    try:
        from supportnode.sim.scene import load_scene
        from supportnode.sim.sensors import sample_scene

        return sample_scene(load_scene("table_chairs"), 108_025).points.astype(
            np.float64
        ), "sim table_chairs"
    except Exception:  # the simulator is optional here
        rng = np.random.default_rng(0)
        p = room(rng)
        return p[rng.choice(p.shape[0], 108_025, replace=False)], "synthetic room"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument(
        "--real",
        default=os.path.join(os.path.dirname(__file__), "..", "..", "shared", "real_scans"),
    )
    ap.add_argument("--docs", action="store_true", help=f"write the table into {DOCS}")
    args = ap.parse_args()
    load = os.getloadavg()
    lines: list[str] = []

    def emit(line: str) -> None:  # printed, and kept for the docs block
        lines.append(line)
        print(line, flush=True)

    pts, name = cloud_108k()
    estimate_normals(pts[:1000], k=30)  # compile or load the kernels first
    t = median_time(lambda: estimate_normals(pts, k=30), args.repeat)
    t_o3d = open3d_normals(pts, args.repeat)
    peer = "- | -" if t_o3d is None else f"{t_o3d:.3f} | {t / t_o3d:.2f}"
    emit("| step | cloud | points | median s | report s | o3d s | ours/o3d |")
    emit("|---|---|---|---|---|---|---|")
    emit(f"| normals k=30 | {name} | {pts.shape[0]:,} | {t:.3f} | {REPORT_NORMALS_S} | {peer} |")

    rng = np.random.default_rng(1)
    rot = rpy(30, 20, 70)
    for density, label in ((1770.0, "100k"), (5300.0, "300k")):
        cloud = apply_rotation(room(rng, density=density) - [0.5, -1, 1.5], rot)
        est = estimate_gravity(cloud)
        err = angle_deg(est.up, rot @ np.array([0, 0, 1.0]))
        t = median_time(lambda c=cloud: estimate_gravity(c), args.repeat)
        emit(
            f"| gravity | synthetic room {label}, tilt 30/20 | {cloud.shape[0]:,} | {t:.3f} | - | error {err:.3f} deg"
        )

    try:
        from supportnode.sim.noise import apply_tilt
        from supportnode.sim.scene import bundled_scenes, load_scene
        from supportnode.sim.sensors import sample_scene
    except ImportError:
        emit("simulator not available: sim scenes skipped")
    else:
        errs = []
        for scene in bundled_scenes():
            for roll, pitch in ((5, -3), (20, 15), (-40, 30)):
                sc = apply_tilt(sample_scene(load_scene(scene), 200_000, seed=2), roll, pitch)
                p = sc.points.astype(np.float64)
                t = time.perf_counter()
                est = estimate_gravity(p)
                dt = time.perf_counter() - t
                e = angle_deg(est.up, sc.tilt_rotation @ np.array([0, 0, 1.0]))
                errs.append(e)
                emit(
                    f"| gravity | sim {scene} tilt {roll},{pitch} | {p.shape[0]:,} | {dt:.3f} | - | error {e:.3f} deg"
                )
        if errs:
            emit(
                f"sim scenes: max error {max(errs):.3f} deg, median {statistics.median(errs):.3f} deg"
            )

    files = sorted(glob.glob(os.path.join(args.real, "*.pcd")))
    try:
        from supportnode.io.clouds import read_cloud
    except ImportError:
        files = []
        emit("reader supportnode.io.clouds not available: real scans skipped")
    for path in files:
        p = read_cloud(path).points.astype(np.float64)
        if np.abs(p).max() > 100:  # the SICK file is in millimetres
            p = p / 1000.0
        for hint in ((0.0, 0.0, 0.0), (0.0, -1.0, 0.0)):
            t = time.perf_counter()
            try:
                est = estimate_gravity(p, GravityParams(up_hint=hint))
            except Exception as err:  # report and go on
                emit(
                    f"| gravity | {os.path.basename(path)} hint {hint} | {p.shape[0]:,} | error: {err}"
                )
                continue
            dt = time.perf_counter() - t
            emit(
                f"| gravity | {os.path.basename(path)} hint {hint} | {p.shape[0]:,} | {dt:.3f} | - | "
                f"up {np.round(est.up, 3).tolist()} tilt {est.tilt_deg:.1f} deg, "
                f"{est.inliers} inliers, residual {est.residual_deg:.2f} deg"
            )
    if args.docs:
        command = docs_command("bench_normals_gravity.py", sys.argv[1:])
        write_docs_block(DOCS, "bench_normals_gravity", "\n".join(lines), command, host_load(load))
        print(f"wrote {DOCS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
