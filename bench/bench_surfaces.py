"""Support-surface detection at the report's sizes, Algorithm 1 (seed) and the planar default.

Run: python bench/bench_surfaces.py [--repeats 5]
Prints median seconds per method next to the report's times (AMD Ryzen 5 3600, Python 3.8).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import median_time, sampled_scene, table

from supportnode.geometry.surfaces import detect_surfaces
from supportnode.params import SurfaceParams

# (label, scene, points, voxel size used by the report, report's time in seconds)
CASES = [
    ("table with 2 chairs", "table_chairs", 108_025, (0.1, 0.1, 0.05), 0.625),
    ("shelf with 8 items", "shelf", 539_034, (0.1, 0.1, 0.07), 2.859),
    ("table, sampled", "table_chairs", 2_000_000, (0.1, 0.1, 0.05), 14.75),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rows = []
    for label, scene, n, voxel, report in CASES:
        pts = sampled_scene(scene, n).points.astype("float64")
        seed = SurfaceParams(method="seed", voxel_size=voxel)
        planar = SurfaceParams(method="planar", voxel_size=voxel)
        t_seed = median_time(lambda p=seed, x=pts: detect_surfaces(x, p), args.repeats)
        t_planar = median_time(lambda p=planar, x=pts: detect_surfaces(x, p), args.repeats)
        rows.append(
            [
                label,
                n,
                "x".join(map(str, voxel)),
                report,
                t_seed,
                t_planar,
                f"{report / t_planar:.0f}x",
            ]
        )
    print(table(rows, ["cloud", "points", "voxel m", "report s", "seed s", "planar s", "speed-up"]))


if __name__ == "__main__":
    main()
