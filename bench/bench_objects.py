"""Object segmentation at the report's sizes: Algorithm 2 (knn), voxels and the convex default.

Run: python bench/bench_objects.py [--repeats 5] [--docs]
Prints median seconds per method next to the report's times (AMD Ryzen 5 3600, Python 3.8), on
mesh-sampled simulator clouds whose surfaces come from the planar detector (timed apart), and,
where ``open3d`` is installed (the ``bench`` extra), Open3D's ``cluster_dbscan`` on the same
candidates (the points on no surface; eps the voxel method's cell, 3 cm, 10 points) with the
default (convex) time as a ratio of it, and one JSON line of the medians for bench/ab.py;
``--docs`` writes that table into docs/performance.md. Then
how many ground-truth touching groups each setting separates, in those clouds and in Kinect
views of the same scenes (the convex method segments only what is sampled densely enough
to show faces: a depth camera's view), then the default detection on tabletop views where
objects of one height touch or a neck rule could part one object (share / purity of each
object's main cluster).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import docs_command, host_load, median_time, sampled_scene, table, write_docs_block

from supportnode.geometry.objects import detect_objects
from supportnode.geometry.surfaces import detect_surfaces
from supportnode.params import DetectParams, ObjectParams, SurfaceParams
from supportnode.pipeline import detect
from supportnode.sim import tabletop
from supportnode.sim.depth_noise import kinect_noise
from supportnode.sim.scene import load_scene
from supportnode.sim.sensors import DepthCamera
from supportnode.sim.trajectory import look_at

# Kinect views of the touching groups (scene, eye, target; world, metres): the shelf's
# barrels from the front at 0.9 m, the U-table's cans and boxes from 1 m, 45 deg down.
VIEWS = [
    ("shelf", (0.0, -0.9, 0.75), (0.0, -0.05, 0.5)),
    ("u_table", (0.34, -1.6, 1.4), (0.34, -0.7, 0.85)),
]
# (label, scene, points, report's k, report's time in seconds); s = 0.3 in both.
CASES = [
    ("table with 2 chairs", "table_chairs", 108_025, 20, 12.75),
    ("shelf with 8 items", "shelf", 539_034, 50, 187.00),
]


DOCS = Path(__file__).resolve().parents[1] / "docs" / "performance.md"


def open3d_dbscan(pts: np.ndarray, repeats: int) -> float | None:
    """Median seconds of Open3D's ``cluster_dbscan`` on ``pts`` (eps the voxel method's
    cell), None without open3d."""
    try:
        import open3d as o3d
    except ImportError:
        return None
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    eps = ObjectParams().cluster_cell
    return median_time(lambda: cloud.cluster_dbscan(eps=eps, min_points=10), repeats)


def timings(repeats: int) -> tuple[str, dict]:
    """The timings table and its medians by scene, seconds (for bench/ab.py)."""
    rows, medians = [], {}
    for label, scene, n, k, report in CASES:
        pts = sampled_scene(scene, n).points.astype(np.float64)
        surf = detect_surfaces(pts, SurfaceParams())
        knn = ObjectParams(method="knn", k=k, sample_fraction=0.3)
        vox = ObjectParams(method="voxel")
        vox_nosplit = ObjectParams(method="voxel", split_touching=False)
        convex = ObjectParams()  # the default: convex segmentation where dense, then splits
        t_knn = median_time(lambda p=knn, x=pts, s=surf: detect_objects(x, s, p), repeats)
        t_vox = median_time(lambda p=vox, x=pts, s=surf: detect_objects(x, s, p), repeats)
        t_vns = median_time(lambda p=vox_nosplit, x=pts, s=surf: detect_objects(x, s, p), repeats)
        t_cvx = median_time(lambda p=convex, x=pts, s=surf: detect_objects(x, s, p), repeats)
        cand = surf.labels == -1
        speed_up = f"{report / t_cvx:.0f}x"
        t_o3d = open3d_dbscan(pts[cand], repeats)
        peer = ["-", "-"] if t_o3d is None else [t_o3d, f"{t_cvx / t_o3d:.2f}"]
        row = [label, n, int(cand.sum()), k, report, t_knn, t_vox, t_vns, t_cvx, speed_up]
        rows.append(row + peer)
        medians[scene] = {"knn_s": t_knn, "voxel_s": t_vox, "convex_s": t_cvx}
    return table(
        rows,
        [
            "cloud",
            "points",
            "candidates",
            "k",
            "report s",
            "knn s",
            "voxel s",
            "voxel no-split s",
            "convex s",
            "speed-up",
            "o3d dbscan s",
            "convex/o3d",
        ],
    ), medians


def touching(
    cloud, names: dict[int, str], params: ObjectParams, eye=None
) -> tuple[int, int, list[str]]:
    """(touching groups, groups separated, names of unseparated groups) in a simulated cloud.

    A touching group: ground-truth objects that the candidates' connected voxels (the voxel
    method without splits) put in one cluster. Separated: every object of the group ends in
    a different cluster (by majority). eye: the sensor's position (a camera's view), None for
    a mesh-sampled cloud."""
    pts = cloud.points.astype(np.float64)
    ok = np.isfinite(pts).all(axis=1)
    pts, truth = pts[ok], cloud.object[ok]
    base = _labels(pts, ObjectParams(method="voxel", split_touching=False), eye)
    res = _labels(pts, params, eye)
    groups = []
    obj_ids = [o for o in np.unique(truth) if o >= 0]
    majority_base = {o: _majority(base[truth == o]) for o in obj_ids}
    for c in {v for v in majority_base.values() if v >= 0}:
        members = [o for o, v in majority_base.items() if v == c]
        if len(members) >= 2:
            groups.append(members)
    separated, missed = 0, []
    for members in groups:
        got = [_majority(res[truth == o]) for o in members]
        if len(set(got)) == len(got) and min(got) >= 0:
            separated += 1
        else:
            missed.append("+".join(names.get(int(o), str(o)) for o in members))
    return len(groups), separated, missed


def _labels(pts: np.ndarray, params: ObjectParams, eye) -> np.ndarray:
    """(N,) object label of each point (-1 none): a sampled cloud's surfaces then objects; a
    camera view through the whole detection, the sensor at eye."""
    if eye is None:
        return detect_objects(pts, detect_surfaces(pts, SurfaceParams()), params).labels
    detect_params = dataclasses.replace(DetectParams(), objects=params)
    return detect(pts, detect_params, sensor_origin=np.asarray(eye, float)).objects.labels


# Kinect views at 1 m of tabletop scenes (name, builder, azimuths in degrees) where objects
# of one height touch, and where a neck rule could part one object wrongly.
HAZARDS = [
    ("two cans touching", lambda: tabletop.two_cans(0.0), (0.0, 30.0, -45.0)),
    ("three cans in a row", tabletop.three_cans, (-60.0, -30.0, 0.0, 30.0, 60.0)),
    ("two boxes, one set back", tabletop.offset_boxes, (-60.0, -30.0, 0.0, 30.0, 60.0)),
    ("bottle 2 cm before a book", tabletop.bottle_before_book, (-20.0, 0.0, 20.0)),
    ("box on a book's edge", tabletop.box_on_book, (-60.0, -30.0, 0.0, 30.0, 60.0, 90.0)),
]


def hazard_rows() -> list[list[object]]:
    """Per hazard view: each object's share in its main cluster / that cluster's purity."""
    rows = []
    for name, build, azimuths in HAZARDS:
        scene = build()
        for az in azimuths:
            cloud = tabletop.view(scene, 1.0, 0, "optical", azimuth_deg=az)
            ok = np.isfinite(cloud.points[:, 0])
            pts, truth = cloud.points[ok].astype(np.float64), cloud.object[ok]
            lab = detect(pts, align=True, sensor_origin=np.zeros(3), origin_assumed=True)
            lab = lab.objects.labels
            cells = []
            for g in np.unique(truth[truth >= 0]):
                mine = truth == g
                best = _majority(lab[mine])
                share = (lab[mine] == best).mean()
                purity = (mine & (lab == best)).sum() / max((lab == best).sum(), 1)
                cells.append(f"{scene.object_names[g]} {share:.2f}/{purity:.2f}")
            rows.append([name, f"{az:.0f}", ", ".join(cells)])
    return rows


def camera_view(scene_name: str, eye, target, seed: int = 0):
    """A Kinect's organised view of the scene from eye towards target (world, metres), with
    its noise; world frame."""
    scene = load_scene(scene_name)
    camera = DepthCamera.preset("kinect")
    cloud = camera.scan(
        scene, look_at(np.asarray(eye, float), np.asarray(target, float)), organized=True
    )
    return kinect_noise(cloud, scene, camera, np.random.default_rng(seed))


def sampled_names(scene: str) -> dict[int, str]:
    return dict(enumerate(load_scene(scene).object_names))


def _majority(lab: np.ndarray) -> int:
    lab = lab[lab >= 0]
    return int(np.bincount(lab).argmax()) if len(lab) else -1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--docs", action="store_true", help=f"write the timings into {DOCS}")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats must be at least 1, got {args.repeats}")
    load = os.getloadavg()
    text, medians = timings(args.repeats)
    print(text)
    print(json.dumps({"objects": medians}))
    if args.docs:
        command = docs_command("bench_objects.py", sys.argv[1:])
        write_docs_block(DOCS, "bench_objects", text, command, host_load(load))
    print()
    rows = []
    clouds = [
        (scene, f"sampled {n:,}", sampled_scene(scene, n), None)
        for scene, n in (("shelf", 539_034), ("u_table", 300_000))
    ] + [
        (scene, "kinect view", camera_view(scene, eye, target), eye) for scene, eye, target in VIEWS
    ]
    for scene, label_cloud, cloud, eye in clouds:
        names = sampled_names(scene)
        for label, p in (
            ("voxel + split", ObjectParams(method="voxel")),
            ("knn s=1 + split", ObjectParams(method="knn", sample_fraction=1.0, k=20)),
            ("convex + split", ObjectParams(method="convex")),
        ):
            groups, sep, missed = touching(cloud, names, p, eye)
            rows.append([scene, label_cloud, label, groups, sep, ", ".join(missed) or "-"])
    print(
        table(rows, ["scene", "cloud", "setting", "touching groups", "separated", "not separated"])
    )
    print()
    print(table(hazard_rows(), ["tabletop view", "azimuth", "object share / purity"]))


if __name__ == "__main__":
    main()
