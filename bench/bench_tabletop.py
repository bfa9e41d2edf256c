"""The simulator's tabletop side: what the Kinect noise model measures on a wall, how a
simulated table compares with the real labelled Kinect tables (mOSD), and how long each
tabletop test case (supportnode.sim.tabletop) takes to build and scan.

Run: python bench/bench_tabletop.py [--repeats 3] [--real ../shared/real_scans/mosd_learn]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import median_time, table

from supportnode.io.clouds import read_cloud
from supportnode.sim import DepthCamera, look_at, parse_scene
from supportnode.sim.depth_noise import DISPARITY_STEP, KINECT_BASELINE, kinect_noise
from supportnode.sim.tabletop import CASES, case, flat_book, view

REPO = Path(__file__).resolve().parents[1]

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


def table_noise(points: np.ndarray, cell: float = 0.08) -> tuple[float, float, float]:
    """(median range m, median incidence deg, median over 8 cm cells of the points' spread off
    the cell's own plane, mm) of table points (N, 3) in the camera frame."""
    centred = points - points.mean(axis=0)
    basis = np.linalg.svd(centred[::50], full_matrices=False)[2]
    rays = points / np.linalg.norm(points, axis=1, keepdims=True)
    incidence = np.degrees(np.arccos(np.median(np.abs(rays @ basis[2]))))
    key = np.floor(centred @ basis[:2].T / cell).astype(np.int64)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    spread = []
    for k in np.flatnonzero(counts > 200):
        q = points[inverse.reshape(-1) == k]
        q = q - q.mean(axis=0)
        spread.append(np.linalg.svd(q, full_matrices=False)[1][2] / np.sqrt(len(q)))
    rng = float(np.median(np.linalg.norm(points, axis=1)))
    return rng, float(incidence), 1000.0 * float(np.median(spread))


def real_rows(folder: Path) -> list[list]:
    """Every 5th mOSD scan's table (labels 1-9), then simulated tables at their ranges and
    incidences (sampled views of supportnode.sim.tabletop, --noise kinect)."""
    rows = []
    for path in sorted(folder.glob("learn*.pcd"), key=lambda p: int(p.stem[5:]))[::5]:
        cloud = read_cloud(path)
        label = cloud.fields["label"]
        table = cloud.points[(label >= 1) & (label <= 9)].astype(np.float64)
        rows.append([path.name, *table_noise(table)])
    for distance, elevation in ((0.85, 35.0), (0.95, 35.0), (1.0, 42.0), (1.0, 50.0)):
        sim = view(flat_book(), distance, frame="optical", elevation_deg=elevation)
        table = sim.points[np.isfinite(sim.points[:, 0]) & (sim.surface == 1)]
        rows.append([f"sim {distance} m, {elevation:.0f} deg down", *table_noise(table)])
    return [[n, f"{r:.2f}", f"{i:.0f}", f"{s:.2f}"] for n, r, i, s in rows]


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
    parser.add_argument(
        "--real",
        type=Path,
        default=REPO.parent / "shared" / "real_scans" / "mosd_learn",
        help="folder of mOSD learn*.pcd (skipped when absent)",
    )
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
    if args.real.is_dir():
        header = ["table", "range m", "incidence deg", "off local plane mm"]
        print(table(real_rows(args.real), header))
        print()
    print(table(case_rows(args.repeats), ["case", "objects", "stacked", "NaN %", "median s"]))


if __name__ == "__main__":
    main()
