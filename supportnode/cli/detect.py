"""`supportnode detect CLOUD`: surfaces, objects and free space in one cloud file, or in every
scan of a recording (MCAP, ROS 2, ROS 1) or folder of clouds."""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from supportnode.cli._common import add_config_arguments, add_rerun_arguments, positive_seconds
from supportnode.cli._console import Interrupted, print_table, progress
from supportnode.cli._process import long_lived, nothing_left
from supportnode.cli._sequence import add_sequence_arguments, process_sequence

if TYPE_CHECKING:
    import numpy as np

    from supportnode.io.clouds import Cloud
    from supportnode.io.units import UnitsGuess


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "cloud",
        help="point cloud file (.ply .pcd .xyz .txt .csv .npy .npz .obj .las .laz), or a "
        "sequence: a recording (.mcap .bag .db3), a ROS 2 bag folder or a folder of clouds",
    )
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
        help="length unit of the clouds' points (default m; a cloud that looks like cm or mm "
        "is flagged on stderr); outputs are in metres, poses stay metres",
    )
    parser.add_argument("--no-objects", action="store_true", help="surfaces only")
    parser.add_argument(
        "--render", action="store_true", help="also draw result.png (needs the viz extra)"
    )
    add_rerun_arguments(parser, "--view", "the result")
    parser.add_argument(
        "--quiet", action="store_true", help="print nothing but errors and warnings"
    )
    add_sequence_arguments(parser, "sequences (recordings, bags and folders)")
    parser.add_argument(
        "--duration", type=positive_seconds, metavar="S", help="read S seconds from --start"
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
    with long_lived():
        from supportnode.config import load_config
        from supportnode.io.scans import is_sequence

        params = load_config(args.config, args.overrides)
    name = Path(args.cloud).stem
    out_dir = Path(args.out) if args.out else Path("out") / name
    if is_sequence(args.cloud):
        return _run_sequence(args, params, out_dir)
    return _run_cloud(args, params, name, out_dir)


# ---------------------------------------------------------------------------- one cloud


def _run_cloud(args: argparse.Namespace, params: Any, name: str, out_dir: Path) -> int:
    with long_lived():
        from supportnode.config import config_to_dict
        from supportnode.io.results import write_detection
        from supportnode.io.units import UNITS
        from supportnode.kernels import runtime
        from supportnode.kernels.loading import load_lightly
        from supportnode.pipeline import detect

    t0 = time.perf_counter()
    stages = 3 + bool(args.render)
    with progress(f"detect {args.cloud}", stages, "stages", args.quiet) as bar:
        # Compiled kernels load once per process (~0.5-1 s, mostly numba starting up): apart,
        # so that the stage timings are the work on this cloud.
        bar.advance(0, "compiling kernels (once per install)")  # shown only when slow
        with long_lived():
            load_lightly()  # this process only loads kernels (compiles refresh numba themselves)
            kernels_time = runtime.warm()
        bar.advance(0, "reading")
        runtime.keep_freed_memory()  # this process's: the stages reuse freed pages
        t = time.perf_counter()
        cloud, unit, guess = _read(args.cloud, args.units)
        read_time = time.perf_counter() - t
        bar.advance(1, f"detecting in {len(cloud.points):,} points")
        detection = detect(
            cloud.points,
            params,
            align=args.align,
            objects=not args.no_objects,
            sensor_origin=_sensor_origin(args, cloud),
            origin_assumed=args.sensor_origin is None,
        )
        detection.timings = {"kernels": kernels_time, "read": read_time, **detection.timings}
        points = cloud.points if detection.rotation is None else cloud.points @ detection.rotation.T
        bar.advance(1, "writing")
        t = time.perf_counter()
        extra = {"units": {"file": unit, "metres_per_unit": UNITS[unit]}}
        try:
            write_detection(out_dir, name, cloud, points, detection, config_to_dict(params), extra)
            if args.render:
                from supportnode.render import render_result

                bar.advance(1, "rendering")
                render_result(out_dir, out_dir / "result.png")
        except KeyboardInterrupt as err:
            raise Interrupted(f"while writing: partial output left in {out_dir}/") from err
        write_time = time.perf_counter() - t
        bar.advance(1)
    if detection.gravity is not None and detection.gravity.warning:
        print(f"supportnode detect: warning: {detection.gravity.warning}", file=sys.stderr)
    if not detection.surfaces.surfaces:
        print(_nothing_found(args, guess), file=sys.stderr)
    if not args.quiet:
        _summary(args.cloud, cloud, detection, out_dir, write_time, time.perf_counter() - t0)
    if args.view or args.save:
        _rerun(args, params, points, detection)
    elif not args.render:  # files written and closed, no viewer or plotting library to finish
        nothing_left()
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
        if cloud.origin is not None:
            cloud.origin = cloud.origin * scale
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


def _rerun(args: argparse.Namespace, params: Any, points: Any, detection: Any) -> None:
    """The cloud (surface points red, objects by id, the rest grey) and what was found."""
    import numpy as np

    from supportnode.detection.messages import detection_messages
    from supportnode.view.rerun_scene import RerunScene

    colors = np.full((len(points), 3), 150, np.uint8)
    if detection.objects is not None:
        obj = detection.objects.labels
        palette = np.random.default_rng(0).integers(40, 230, (max(int(obj.max()) + 1, 1), 3))
        colors[obj >= 0] = palette[obj[obj >= 0]]
    colors[detection.surfaces.labels >= 0] = (220, 50, 50)
    surfaces, obstacles = detection_messages(detection, params.safe, 0.0, "cloud")
    with RerunScene("save" if args.save else args.view, args.save) as scene:
        scene.log_points(0.0, points, colors)
        scene.log_surfaces(surfaces)
        if obstacles is not None:
            scene.log_obstacles(obstacles)
        if scene.url is not None:
            print(f"rerun: open {scene.url}  (Ctrl-C to stop)", flush=True)
            _wait_for_ctrl_c()
    if args.save and not args.quiet:
        print(f"wrote {args.save} (open it with: rerun {args.save})")


def _wait_for_ctrl_c() -> None:
    import threading

    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass


def _summary(path, cloud, detection, out_dir, write_time: float, total: float) -> None:
    dropped = cloud.dropped_nonfinite
    print(
        f"{path}: {len(cloud.points):,} points"
        + (f" ({dropped:,} NaN/Inf rows dropped)" if dropped else "")
    )
    if cloud.origin is not None:
        print(
            "origin: " + ", ".join(f"{v:.3f}" for v in cloud.origin) + " subtracted (result.json)"
        )
    if detection.gravity is not None:
        print(
            f"gravity: tilt {detection.gravity.tilt_deg:.2f} deg corrected "
            f"({detection.gravity.reason})"
        )
    free = {f.surface_id: f for f in detection.free_space}
    rows = []
    for s in detection.surfaces.surfaces:
        f = free.get(s.id)
        rows.append(
            (
                s.id,
                f"{s.height:.3f}",
                f"{s.area:.2f}",
                f"{s.point_count:,}",
                f"{f.free_area:.2f}" if f else "-",
                f"{f.disc_radius:.2f}" if f else "-",
            )
        )
    print_table(("surface", "height m", "area m2", "points", "free m2", "disc r m"), rows)
    if detection.objects is not None:
        on = sum(c.surface_id is not None for c in detection.objects.clusters)
        print(f"objects: {len(detection.objects.clusters)} clusters ({on} on a surface)")
    stages = ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in detection.timings.items())
    print(f"time: {stages}, write {write_time * 1000:.0f} ms; total {total:.2f} s")
    print(f"wrote {out_dir}/ (result.json, labels.npz, *_detected.ply, *_not_detected.ply)")


# ---------------------------------------------------------------------------- sequences


def _run_sequence(args: argparse.Namespace, params: Any, out_dir: Path) -> int:
    if args.render or args.sensor_origin is not None or args.view or args.save:
        from supportnode.errors import SupportNodeError

        raise SupportNodeError(
            "--render, --view, --save and --sensor-origin are for one cloud; a sequence's "
            "scans carry their poses (see them with: supportnode view OUT/results.mcap --rerun)"
        )
    t0 = time.perf_counter()
    per_scan: list[tuple[int, int, float]] = []  # surfaces, objects, seconds

    def handle(scan: Any, results: Any) -> None:
        per_scan.append(_detect_scan(scan, params, args, results))

    topic, _, selection = process_sequence(
        "detect", args.cloud, args, out_dir / "results.mcap", handle
    )
    if not args.quiet:
        _sequence_summary(args.cloud, topic, per_scan, selection, out_dir, time.perf_counter() - t0)
    return 0


def _detect_scan(scan: Any, params: Any, args: argparse.Namespace, results: Any) -> tuple:
    """One scan of a sequence, in its pose's frame when it has one (the map frame)."""
    import numpy as np

    from supportnode.detection.messages import detection_messages
    from supportnode.geometry.transform import pose_matrix, transform_points
    from supportnode.io.units import UNITS
    from supportnode.pipeline import detect

    t = time.perf_counter()
    points, frame = scan.points * UNITS[args.units or "m"], scan.frame_id
    # Without a pose a scan is in its sensor's frame: the sensor at its origin (an assumption
    # `detect` drops when alignment finds that origin on the floor).
    origin = np.zeros(3) if args.align else None
    if scan.pose is not None:
        pose = pose_matrix(scan.pose.translation, scan.pose.rotation)
        points = transform_points(points, pose[:3, :3], pose[:3, 3])
        origin, frame = pose[:3, 3], params.node.frame_id
    det = detect(
        points,
        params,
        align=args.align,
        objects=not args.no_objects,
        sensor_origin=origin,
        origin_assumed=scan.pose is None,
    )
    surfaces, obstacles = detection_messages(det, params.safe, scan.stamp, frame, scan.seq)
    results.write(scan, surfaces, obstacles, det.timings)
    n_objects = 0 if obstacles is None else len(obstacles.clusters)
    return len(surfaces.surfaces), n_objects, time.perf_counter() - t


def _sequence_summary(path, topic, per_scan, selection, out_dir: Path, total: float) -> None:
    skipped = ", ".join(f"{n} {why}" for why, n in selection.skipped.items())
    print(
        f"{path}: {len(per_scan)} scans on topic {topic!r}"
        + (f" ({skipped} skipped)" if skipped else "")
    )
    if per_scan:
        s, o, t = zip(*per_scan, strict=True)
        rows = [
            ("surfaces", min(s), f"{statistics.median(s):g}", max(s)),
            ("objects", min(o), f"{statistics.median(o):g}", max(o)),
            (
                "ms per scan",
                f"{min(t) * 1e3:.0f}",
                f"{statistics.median(t) * 1e3:.0f}",
                f"{max(t) * 1e3:.0f}",
            ),
        ]
        print_table(("per scan", "min", "median", "max"), rows)
    print(f"time: total {total:.2f} s")
    print(f"wrote {out_dir}/results.mcap (surfaces, obstacles) and {out_dir}/results.jsonl")
