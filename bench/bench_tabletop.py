"""The simulator's tabletop side: what the Kinect noise model measures on a wall, and how long
each tabletop test case (supportnode.sim.tabletop) takes to build and scan.

Run: python bench/bench_tabletop.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import median_time, table

from supportnode.sim import DepthCamera, look_at, parse_scene
from supportnode.sim.depth_noise import DISPARITY_STEP, KINECT_BASELINE, kinect_noise
from supportnode.sim.tabletop import CASES, case

WALL = """
primitives:
  - {kind: box, name: wall, size: [0.02, 8, 8], xyz: [0, 0, 0], role: surface, surface: wall}
"""


def noise_rows() -> list[list]:
    """Depth error on a wall facing the camera at several ranges, against the model."""
    scene, cam = parse_scene(WALL), DepthCamera.preset("kinect")
    rows = []
    for distance in (0.5, 0.75, 1.0, 1.5, 2.0, 3.0):
        pose = look_at([-distance, 0.0, 0.0], [0.0, 0.0, 0.0])
        clean = cam.scan(scene, pose, organized=True)
        noisy = kinect_noise(clean, scene, cam, np.random.default_rng(0))
        ok = np.isfinite(noisy.points[:, 0])
        axis = pose[:3, 0]
        err = (noisy.points[ok] - clean.points[ok]).astype(np.float64) @ axis
        sigma = 0.0012 + 0.0019 * (distance - 0.4) ** 2
        step = distance**2 * DISPARITY_STEP / (cam.focal_px * KINECT_BASELINE)
        rows.append(
            [
                distance,
                f"{1000 * sigma:.2f}",
                f"{1000 * step:.2f}",
                f"{1000 * err.std():.2f}",
                f"{1000 * err.mean():+.2f}",
                f"{100 * (1 - ok.mean()):.2f}",
            ]
        )
    return rows


def case_rows(repeats: int) -> list[list]:
    rows = []
    for name in CASES:
        seconds = median_time(lambda n=name: case(n), repeats)
        c = case(name)
        holes = ~np.isfinite(c.cloud.points[:, 0])
        stacked = int((c.scene.support.supported_by >= 0).sum())
        rows.append(
            [name, len(c.scene.object_names), stacked, f"{100 * holes.mean():.1f}", seconds]
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(
        table(
            noise_rows(),
            [
                "range m",
                "model sigma mm",
                "disparity step mm",
                "measured std mm",
                "mean mm",
                "holes %",
            ],
        )
    )
    print()
    print(table(case_rows(args.repeats), ["case", "objects", "stacked", "NaN %", "median s"]))


if __name__ == "__main__":
    main()
