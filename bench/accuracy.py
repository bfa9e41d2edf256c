"""Accuracy against the simulator's ground truth: surfaces, objects, gravity.

Run: python bench/accuracy.py [--points 150000] [--tilts 8] [--poses 8] [--set k=v] [--docs]
Every simulator figure in docs/accuracy.md comes from this script (seeds fixed; ``--docs``
writes its tables there), the cluttered tabletop's rows included: sampled, one Kinect view
with its noise, and that view from ``--poses`` places along the camera's arc around the
table's front (a scene looks different from each: shadows, occlusions, which objects touch
in the image).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import docs_command, host_load, table, write_docs_block

from supportnode.config import load_config
from supportnode.errors import AlignmentError
from supportnode.geometry.gravity import estimate_gravity
from supportnode.pipeline import detect
from supportnode.sim import load_scene
from supportnode.sim.evaluate import evaluate, format_support, supported_by_of
from supportnode.sim.noise import parse_noise
from supportnode.sim.sensors import DepthCamera, Lidar
from supportnode.sim.simulate import sampled, scans
from supportnode.sim.trajectory import poses_for

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs" / "accuracy.md"
SCENES = ["shelf", "table_chairs", "u_table", "kitchen", "sloped"]
TABLETOPS = ["cluttered_table"]  # seen by a depth camera: sampled and a Kinect view


def score(cloud, params, sensor_origin=None) -> dict:
    det = detect(cloud.points.astype(np.float64), params, sensor_origin=sensor_origin)
    # Support as result.json gives it: "-" until the detection's objects carry supported_by.
    by = supported_by_of(det.to_dict()["objects"])
    return evaluate(
        det.surfaces.labels, det.objects.labels, cloud.surface, cloud.object, cloud.supported_by, by
    )


def row(scene: str, variant: str, ev: dict) -> list:
    s, o = ev["surfaces"], ev["objects"]
    n_gt = s["gt_count"]
    return [
        scene,
        variant,
        f"{s['precision']:.3f}",
        f"{s['recall']:.3f}",
        f"{s['mean_iou']:.2f}",
        f"{s['found']}/{n_gt}",
        s["spurious"],
        f"{o['ari']:.2f}" if o["gt_count"] > 1 else "-",  # ARI needs two objects
        f"{o['found']}/{o['gt_count']}",
        o["merged"],
        o["split"],
        format_support(o["support"]),
    ]


def gravity_errors(scene, n_points: int, tilts: int, seed: int = 0) -> tuple[list[float], int]:
    """Angle between the recovered and true up (deg) over random roll/pitch <= 45, any yaw."""
    rng = np.random.default_rng(seed)
    base = sampled(scene, n_points, seed=seed).points.astype(np.float64)
    errors, failures = [], 0
    for _ in range(tilts):
        roll, pitch = rng.uniform(-45, 45, 2)
        yaw = rng.uniform(-180, 180)
        rot = _rpy(roll, pitch, yaw)
        try:
            est = estimate_gravity(base @ rot.T)
        except AlignmentError:
            failures += 1
            continue
        true_up = rot @ np.array([0.0, 0.0, 1.0])
        errors.append(float(np.degrees(np.arccos(np.clip(est.up @ true_up, -1, 1)))))
    return errors, failures


def gravity_row(name: str, scene, tilts: int) -> list:
    errors, failures = gravity_errors(scene, 100_000, tilts)
    return [
        name,
        len(errors) + failures,
        f"{np.median(errors):.2f}" if errors else "-",
        f"{np.max(errors):.2f}" if errors else "-",
        failures,
    ]


def _rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    r, p, y = np.radians([roll, pitch, yaw])
    rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def poses_table(scene_name: str, n: int, params) -> str:
    """The tabletop seen by a Kinect from n poses along its trajectory: a row per pose and
    their mean ARI."""
    scene = load_scene(scene_name)
    poses = poses_for(scene, n, level=False)
    kinect = DepthCamera.preset("kinect")
    rows, aris = [], []
    for i in range(n):
        view = scans(scene, kinect, poses[i : i + 1], i, parse_noise(["kinect"]))[0]
        ev = score(view, params, view.sensor_pose[:3, 3])
        s, o = ev["surfaces"], ev["objects"]
        aris.append(o["ari"])
        rows.append(
            [
                i,
                f"{s['precision']:.3f}",
                f"{s['recall']:.3f}",
                s["spurious"],
                f"{o['ari']:.2f}",
                f"{o['found']}/{o['gt_count']}",
                o["merged"],
                o["split"],
            ]
        )
    head = ["pose", "surf P", "surf R", "spurious", "obj ARI", "objects", "merged", "split"]
    return (
        f"{scene_name}, Kinect from {n} poses:\n"
        + table(rows, head)
        + f"\nmean object ARI {np.mean(aris):.3f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=150_000)
    parser.add_argument("--tilts", type=int, default=8, help="random tilts per scene for gravity")
    parser.add_argument(
        "--poses", type=int, default=8, help="Kinect poses around the cluttered tabletop"
    )
    parser.add_argument(
        "--docs", action="store_true", help="write the tables into docs/accuracy.md"
    )
    parser.add_argument("--set", action="append", default=[], help="config override key=value")
    args = parser.parse_args()
    load = os.getloadavg()
    default = load_config(None, args.set)
    noisy = load_config(REPO / "config" / "noisy.yaml", args.set)
    report_noise = parse_noise(["uniform:0.05"])
    rows, grav_rows = [], []
    for name in SCENES:
        scene = load_scene(name)
        rows.append(row(name, "sampled", score(sampled(scene, args.points, seed=0), default)))
        rows.append(
            row(name, "sampled+noise", score(sampled(scene, args.points, 0, report_noise), noisy))
        )
        lidar = scans(scene, Lidar.preset("os128"), poses_for(scene, 1), seed=0)[0]
        rows.append(row(name, "os128 scan", score(lidar, default, lidar.sensor_pose[:3, 3])))
        grav_rows.append(gravity_row(name, scene, args.tilts))
    for name in TABLETOPS:
        scene = load_scene(name)
        rows.append(row(name, "sampled", score(sampled(scene, args.points, seed=0), default)))
        pose = poses_for(scene, 1, level=False)
        view = scans(scene, DepthCamera.preset("kinect"), pose, 0, parse_noise(["kinect"]))[0]
        rows.append(row(name, "kinect view", score(view, default, view.sensor_pose[:3, 3])))
        grav_rows.append(gravity_row(name, scene, args.tilts))
    text = (
        table(
            rows,
            [
                "scene",
                "cloud",
                "surf P",
                "surf R",
                "mean IoU",
                "surfaces",
                "spurious",
                "obj ARI",
                "objects",
                "merged",
                "split",
                "supported_by (stacked)",
            ],
        )
        + "\n\n"
        + table(grav_rows, ["scene", "tilts", "median err deg", "max err deg", "refused"])
    )
    if args.poses > 0:
        text += "\n\n" + poses_table(TABLETOPS[0], args.poses, default)
    print(text)
    if args.docs:
        command = docs_command("accuracy.py", sys.argv[1:])
        write_docs_block(DOCS, "accuracy", text, command, host_load(load))
        print(f"wrote {DOCS}")


if __name__ == "__main__":
    main()
