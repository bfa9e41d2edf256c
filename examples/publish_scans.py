"""Publish the NPZ lidar frames of a folder as PointCloud messages, in a loop, like a driver.

    python examples/publish_scans.py sim_scans/table_chairs_lidar --rate 10

Each frame of ``supportnode sim --sensor lidar`` (``frame_*.npz``: points, sensor_pose 4x4
sensor-to-world, frame "world" or "sensor") goes out in the sensor frame (``frame_id`` lidar)
with the sensor's pose, as a real driver plus localisation would send it; stamps are the
wall clock. Binds the endpoint (drivers bind, the node connects). Ctrl-C or SIGTERM: exit 0.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from supportnode.client import Publisher


def load_frames(folder: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """(points in the sensor frame (N, 3) float32, sensor-to-world pose (4, 4)) per frame file."""
    files = sorted(folder.glob("frame_*.npz"))
    if not files:
        raise SystemExit(f"publish_scans: no frame_*.npz in {folder}")
    frames = []
    for path in files:
        with np.load(path) as data:
            points = np.asarray(data["points"], dtype=np.float64)
            pose = np.asarray(data["sensor_pose"], dtype=np.float64)
            frame = str(data["frame"]) if "frame" in data.files else "world"
        if frame == "world":  # to the sensor frame: p_s = R^T (p_w - t)
            points = (points - pose[:3, 3]) @ pose[:3, :3]
        frames.append((points.astype(np.float32), pose))
    return frames


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="folder of frame_*.npz files")
    parser.add_argument("--endpoint", default="tcp://127.0.0.1:5555")
    parser.add_argument("--topic", default="scan")
    parser.add_argument("--connect", action="store_true", help="connect instead of binding")
    parser.add_argument("--rate", type=float, default=10.0, help="frames per second")
    parser.add_argument("--once", action="store_true", help="publish every frame once, then exit")
    args = parser.parse_args(argv)

    frames = load_frames(args.folder)
    # SIGINT and SIGTERM end it like Ctrl-C, also when it was started with SIGINT ignored
    # (a background job of a script): Python then leaves SIGINT ignored.
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.default_int_handler)
    period = 1.0 / args.rate
    try:
        with Publisher(args.endpoint, args.topic, bind=not args.connect) as pub:
            print(
                f"publish_scans: {len(frames)} frames on {pub.endpoint} topic {args.topic} "
                f"at {args.rate:g} Hz",
                flush=True,
            )
            next_time = time.monotonic()
            while True:
                for points, pose in frames:
                    cloud = pub.publish_cloud(points, frame_id="lidar", pose=pose)
                    if cloud.seq % 50 == 1:
                        print(
                            f"publish_scans: sent seq {cloud.seq} ({cloud.count} points)",
                            flush=True,
                        )
                    # Fixed rate without drift: sleep to the next tick, not for a whole period.
                    next_time += period
                    time.sleep(max(0.0, next_time - time.monotonic()))
                if args.once:
                    break
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
