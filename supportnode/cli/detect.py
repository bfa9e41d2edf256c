"""`supportnode detect CLOUD`: surfaces, objects and free space in one cloud file."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from supportnode.cli._common import add_config_arguments

if TYPE_CHECKING:
    import numpy as np

    from supportnode.io.clouds import Cloud
    from supportnode.io.units import UnitsGuess


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
        help="sensor position in the cloud's frame, metres: planes above it are undersides "
        "(with --align default: the PCD viewpoint, else 0,0,0: the cloud is the sensor's)",
    )
    parser.add_argument(
        "--units",
        choices=("m", "cm", "mm"),
        help="length unit of the file (default m; a cloud that looks like cm or mm is "
        "flagged on stderr); outputs are in metres",
    )
    parser.add_argument("--no-objects", action="store_true", help="surfaces only")
    parser.add_argument(
        "--render", action="store_true", help="also draw result.png (needs the viz extra)"
    )
    parser.add_argument(
        "--quiet", action="store_true", help="print nothing but errors and warnings"
    )


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
    from supportnode.io.results import write_detection
    from supportnode.io.units import UNITS
    from supportnode.kernels import runtime
    from supportnode.pipeline import detect

    t0 = time.perf_counter()
    params = load_config(args.config, args.overrides)
    # Compiled kernels load once per process (~0.5-1 s, mostly numba starting up): apart, so
    # that the stage timings are the work on this cloud.
    kernels_time = runtime.warm()
    t = time.perf_counter()
    cloud, unit, guess = _read(args.cloud, args.units)
    read_time = time.perf_counter() - t
    name = Path(args.cloud).stem
    out_dir = Path(args.out) if args.out else Path("out") / name
    detection = detect(
        cloud.points,
        params,
        align=args.align,
        objects=not args.no_objects,
        sensor_origin=_sensor_origin(args, cloud),
        origin_assumed=args.sensor_origin is None,
    )
    detection.timings = {"kernels": kernels_time, "read": read_time, **detection.timings}
    if detection.gravity is not None and detection.gravity.warning:
        print(f"supportnode detect: warning: {detection.gravity.warning}", file=sys.stderr)
    if not detection.surfaces.surfaces:
        print(_nothing_found(args, guess), file=sys.stderr)
    points = cloud.points if detection.rotation is None else cloud.points @ detection.rotation.T
    t = time.perf_counter()
    extra = {"units": {"file": unit, "metres_per_unit": UNITS[unit]}}
    written = write_detection(
        out_dir, name, cloud, points, detection, config_to_dict(params), extra
    )
    if args.render:
        from supportnode.render import render_result

        written.append(render_result(out_dir, out_dir / "result.png"))
    write_time = time.perf_counter() - t
    if not args.quiet:
        print(_summary(args.cloud, cloud, detection, out_dir, write_time, time.perf_counter() - t0))
    return 0


def _read(path: str, unit: str | None) -> tuple[Cloud, str, UnitsGuess | None]:
    """The cloud in metres, the unit it was read in, and the guess made when none was given
    (said on stderr when it is not metres). A flagged cloud is still read as metres: a guess
    must never stop a valid cloud, and the summary shows what came of it."""
    import numpy as np

    from supportnode.io.clouds import read_cloud
    from supportnode.io.units import UNITS, guess_units

    cloud = read_cloud(path)
    if unit is None:
        guess = guess_units(cloud.points)
        message = guess.message(path)
        if message:
            print(f"supportnode detect: warning: {message}", file=sys.stderr)
        return cloud, "m", guess
    scale = UNITS[unit]
    if scale != 1.0:
        cloud.points = cloud.points * scale
        if cloud.viewpoint is not None:
            cloud.viewpoint = np.concatenate([cloud.viewpoint[:3] * scale, cloud.viewpoint[3:]])
    return cloud, unit, None


def _sensor_origin(args: argparse.Namespace, cloud: Cloud) -> np.ndarray | None:
    """Where the sensor was: --sensor-origin; with --align the cloud is in the sensor's own
    frame, so the PCD viewpoint or the frame's origin; otherwise unknown (None)."""
    import numpy as np

    if args.sensor_origin is not None:
        return np.asarray(args.sensor_origin, dtype=np.float64)
    if not args.align:
        return None
    return np.zeros(3) if cloud.viewpoint is None else np.asarray(cloud.viewpoint[:3], float)


def _nothing_found(args: argparse.Namespace, guess: UnitsGuess | None) -> str:
    """What to check when no surface was found: one line, the likely causes first."""
    checks = []
    if guess is not None and guess.unit != "m":
        checks.append(f"the units (it looks like {guess.unit}: --units {guess.unit})")
    elif guess is not None:
        checks.append("the units (read as metres; --units mm or --units cm)")
    if not args.align:
        checks.append("that z points up (a camera-frame cloud needs --align)")
    else:
        checks.append("the alignment (--set gravity.up_hint=[x,y,z] if the up found is wrong)")
    checks.append("the surface limits (surfaces.min_area, surfaces.max_tilt_deg)")
    return f"supportnode detect: warning: {args.cloud}: no surface found; check " + ", ".join(
        checks
    )


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
        lines.append(
            f"gravity: tilt {detection.gravity.tilt_deg:.2f} deg corrected "
            f"({detection.gravity.reason})"
        )
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
