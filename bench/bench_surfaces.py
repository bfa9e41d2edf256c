"""Support-surface detection at the report's sizes, Algorithm 1 (seed) and the planar default.

Run: python bench/bench_surfaces.py [--repeats 5] [--docs]
Prints median seconds per method next to the report's times (AMD Ryzen 5 3600, Python 3.8)
and, where ``open3d`` is installed (the ``bench`` extra), Open3D's ``segment_plane`` (RANSAC,
2 cm, 1,000 iterations: one plane, not all the surfaces) on the same cloud in the same run,
with our planar time as a ratio of it. ``--docs`` writes the table into docs/performance.md.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import docs_command, host_load, median_time, sampled_scene, table, write_docs_block

from supportnode.geometry.surfaces import detect_surfaces
from supportnode.params import SurfaceParams

DOCS = Path(__file__).resolve().parents[1] / "docs" / "performance.md"

# (label, scene, points, voxel size used by the report, report's time in seconds)
CASES = [
    ("table with 2 chairs", "table_chairs", 108_025, (0.1, 0.1, 0.05), 0.625),
    ("shelf with 8 items", "shelf", 539_034, (0.1, 0.1, 0.07), 2.859),
    ("table, sampled", "table_chairs", 2_000_000, (0.1, 0.1, 0.05), 14.75),
]


def open3d_plane(pts: np.ndarray, repeats: int) -> float | None:
    """Median seconds of Open3D's ``segment_plane`` on ``pts``, None without open3d."""
    try:
        import open3d as o3d
    except ImportError:
        return None
    o3d.utility.random.seed(0)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    return median_time(
        lambda: cloud.segment_plane(distance_threshold=0.02, ransac_n=3, num_iterations=1000),
        repeats,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--docs", action="store_true", help=f"write the table into {DOCS}")
    args = parser.parse_args()
    load = os.getloadavg()
    rows = []
    for label, scene, n, voxel, report in CASES:
        pts = sampled_scene(scene, n).points.astype("float64")
        seed = SurfaceParams(method="seed", plane_voxel=voxel)
        planar = SurfaceParams(method="planar", plane_voxel=voxel)
        t_seed = median_time(lambda p=seed, x=pts: detect_surfaces(x, p), args.repeats)
        t_planar = median_time(lambda p=planar, x=pts: detect_surfaces(x, p), args.repeats)
        t_o3d = open3d_plane(pts, args.repeats)
        rows.append(
            [
                label,
                n,
                "x".join(map(str, voxel)),
                report,
                t_seed,
                t_planar,
                f"{report / t_planar:.0f}x",
                "-" if t_o3d is None else t_o3d,
                "-" if t_o3d is None else f"{t_planar / t_o3d:.2f}",
            ]
        )
    header = ["cloud", "points", "voxel m", "report s", "seed s", "planar s", "speed-up"]
    text = table(rows, [*header, "o3d plane s", "planar/o3d"])
    print(text)
    if args.docs:
        command = docs_command("bench_surfaces.py", sys.argv[1:])
        write_docs_block(DOCS, "bench_surfaces", text, command, host_load(load))
        print(f"wrote {DOCS}")


if __name__ == "__main__":
    main()
