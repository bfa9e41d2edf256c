"""`supportnode detect CLOUD`: surfaces, objects and free space in one cloud file."""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from supportnode.cli._common import add_config_arguments


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("cloud", help="point cloud file (.ply .pcd .xyz .txt .csv .npy .npz .obj)")
    add_config_arguments(parser, "surfaces.method=seed")
    parser.add_argument("--out", metavar="DIR", help="output folder (default: out/<cloud name>)")
    parser.add_argument(
        "--align",
        action="store_true",
        help="rotate the cloud to gravity from its normals first (no IMU; z is not up)",
    )
    parser.add_argument(
        "--sensor-origin",
        metavar="X,Y,Z",
        type=_xyz,
        help="sensor position in the cloud's frame, metres: planes above it are undersides",
    )
    parser.add_argument("--no-objects", action="store_true", help="surfaces only")
    parser.add_argument(
        "--render", action="store_true", help="also draw result.png (needs the viz extra)"
    )
    parser.add_argument("--quiet", action="store_true", help="print nothing but errors")


def _xyz(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(map(math.isfinite, values)):
        raise argparse.ArgumentTypeError(f"expected X,Y,Z in metres, got {text!r}")
    return values  # type: ignore[return-value]


def run(args: argparse.Namespace) -> int:
    from supportnode.config import config_to_dict, load_config
    from supportnode.io.clouds import read_cloud
    from supportnode.io.results import write_detection
    from supportnode.pipeline import detect

    t0 = time.perf_counter()
    params = load_config(args.config, args.overrides)
    t = time.perf_counter()
    cloud = read_cloud(args.cloud)
    read_time = time.perf_counter() - t
    name = Path(args.cloud).stem
    out_dir = Path(args.out) if args.out else Path("out") / name
    detection = detect(
        cloud.points,
        params,
        align=args.align,
        objects=not args.no_objects,
        sensor_origin=args.sensor_origin,
    )
    detection.timings = {"read": read_time, **detection.timings}
    points = cloud.points if detection.rotation is None else cloud.points @ detection.rotation.T
    t = time.perf_counter()
    written = write_detection(out_dir, name, cloud, points, detection, config_to_dict(params))
    if args.render:
        from supportnode.render import render_result

        written.append(render_result(out_dir, out_dir / "result.png"))
    write_time = time.perf_counter() - t
    if not args.quiet:
        print(_summary(args.cloud, cloud, detection, out_dir, write_time, time.perf_counter() - t0))
    return 0


def _summary(path, cloud, detection, out_dir, write_time: float, total: float) -> str:
    lines = [
        f"{path}: {len(cloud.points):,} points"
        + (
            f" ({cloud.dropped_nonfinite:,} NaN/Inf rows dropped)"
            if cloud.dropped_nonfinite
            else ""
        )
    ]
    if detection.gravity is not None:
        lines.append(f"gravity: tilt {detection.gravity.tilt_deg:.2f} deg corrected")
    free = {f.surface_id: f for f in detection.free_space}
    lines.append(
        f"{'surface':>7} {'height m':>9} {'area m2':>8} {'points':>9} {'free m2':>8} {'disc r m':>8}"
    )
    for s in detection.surfaces.surfaces:
        f = free.get(s.id)
        fa = f"{f.free_area:8.2f}" if f else f"{'-':>8}"
        fr = f"{f.disc_radius:8.2f}" if f else f"{'-':>8}"
        lines.append(f"{s.id:>7} {s.height:9.3f} {s.area:8.2f} {s.point_count:9,} {fa} {fr}")
    if detection.objects is not None:
        on = sum(c.surface_id is not None for c in detection.objects.clusters)
        lines.append(f"objects: {len(detection.objects.clusters)} clusters ({on} on a surface)")
    stages = ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in detection.timings.items())
    lines.append(f"time: {stages}, write {write_time * 1000:.0f} ms; total {total:.2f} s")
    lines.append(f"wrote {out_dir}/ (result.json, labels.npz, *_detected.ply, *_not_detected.ply)")
    return "\n".join(lines)
