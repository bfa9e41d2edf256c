"""Simulator timings: median wall time over 5 runs per case, printed as a table.

python3 bench/bench_sim.py            # all bundled scenes
python3 bench/bench_sim.py shelf      # one scene
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import numpy as np

from supportnode.sim import DepthCamera, Lidar, bundled_scenes, load_scene, poses_for, sample_scene

RUNS = 5


def median_time(fn: Callable[[], object]) -> tuple[float, object]:
    """Median seconds over RUNS calls (after one warm-up call) and the last result."""
    result = fn()
    times = []
    for _ in range(RUNS):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def main(names: list[str]) -> None:
    sensors = {
        "os128 (128x1024)": Lidar.preset("os128"),
        "vlp16 (16x1800)": Lidar.preset("vlp16"),
        "camera vga (640x480)": DepthCamera.preset("vga"),
    }
    print(f"{'scene':<14} {'case':<22} {'rays':>9} {'points':>9} {'median s':>9}")
    for name in names:
        scene = load_scene(name)
        lidar_pose = poses_for(scene, 1, level=True)[0]
        camera_pose = poses_for(scene, 1, level=False)[0]
        for label, sensor in sensors.items():
            pose = lidar_pose if isinstance(sensor, Lidar) else camera_pose
            seconds, cloud = median_time(lambda s=sensor, p=pose, sc=scene: s.scan(sc, p))
            rays = len(sensor.directions())
            print(f"{name:<14} {label:<22} {rays:>9} {len(cloud):>9} {seconds:>9.3f}")
        seconds, cloud = median_time(lambda sc=scene: sample_scene(sc, 1_000_000, seed=0))
        print(f"{name:<14} {'sample 1M':<22} {'-':>9} {len(cloud):>9} {seconds:>9.3f}")


if __name__ == "__main__":
    main(sys.argv[1:] or bundled_scenes())
