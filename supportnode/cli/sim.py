"""`supportnode sim`: simulate a scene with ground truth and write PLY/NPZ clouds.

supportnode sim shelf --points 200000 --out shelf.ply
supportnode sim table_chairs --sensor lidar --preset os128 --frames 5 --out scans/
supportnode sim kitchen --sensor lidar --preset os128 --frames 50 --out kitchen.mcap
supportnode sim my_scene.yaml --sensor camera --noise range:0.01 --noise tilt:2,1 --out c.npz
supportnode sim tabletop --sensor camera --preset kinect --noise kinect --organized --out k.npz
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from supportnode.cli._console import progress

if TYPE_CHECKING:
    from supportnode.sim.noise import NoiseSpec
    from supportnode.sim.sensors import DepthCamera, Lidar

SENSORS = ("sample", "lidar", "camera")
LIDAR_PRESETS = ("vlp16", "os128")
CAMERA_PRESETS = ("d435", "vga", "kinect")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="bundled scene name (e.g. shelf) or path to a scene YAML")
    parser.add_argument("--quiet", action="store_true", help="no progress, no list of files")
    parser.add_argument(
        "--sensor",
        choices=SENSORS,
        default="sample",
        help="sample: points uniformly by area on every face (default); lidar; camera (depth)",
    )
    parser.add_argument(
        "--preset",
        choices=LIDAR_PRESETS + CAMERA_PRESETS,
        default=None,
        help="lidar: vlp16 (default) or os128; camera: vga (default), d435 or kinect",
    )
    parser.add_argument(
        "--points", type=int, default=200_000, metavar="N", help="points for --sensor sample"
    )
    parser.add_argument(
        "--frames",
        type=int,
        default=1,
        metavar="N",
        help="scans along the scene's trajectory (lidar/camera)",
    )
    parser.add_argument(
        "--noise",
        action="append",
        default=[],
        metavar="SPEC",
        help="uniform:A, gauss:S, range:S, outliers:F, tilt:ROLL,PITCH, kinect[:S] (repeatable)",
    )
    parser.add_argument(
        "--organized",
        action="store_true",
        help="camera: one row per pixel, NaN where nothing returns (like a Kinect PCD)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--frame",
        choices=("world", "sensor", "optical"),
        default="world",
        help="coordinates of the written points: world (default, z up), sensor (x forward, "
        "z up) or optical (camera: z forward, y down)",
    )
    parser.add_argument(
        "--out",
        required=True,
        metavar="PATH",
        help="file.ply / file.npz (one cloud, or file_000... for several), a directory of "
        "frame_NNN.npz, or file.mcap (a recording for supportnode play)",
    )


def run(args: argparse.Namespace) -> int:
    from supportnode.errors import ConfigError
    from supportnode.sim import simulate
    from supportnode.sim.files import write_sim_clouds
    from supportnode.sim.noise import parse_noise
    from supportnode.sim.scene import load_scene
    from supportnode.sim.trajectory import poses_for

    scene = load_scene(args.scene)
    noise = parse_noise(args.noise)
    meta: dict[str, object] = {
        "scene": scene.name,
        "scene_source": scene.source,
        "sensor": args.sensor,
        "noise": list(args.noise),
        "seed": args.seed,
    }
    _check_sensor_args(args, noise)
    if args.sensor == "sample":
        clouds = [simulate.sampled(scene, args.points, args.seed, noise)]
        meta["points"] = args.points
    else:
        preset, sensor = _sensor(args)
        # A lidar rides level on a robot; a camera tilts down to look at the target.
        poses = poses_for(scene, args.frames, level=args.sensor == "lidar")
        with progress(f"sim {scene.name}", len(poses), "frames", args.quiet) as bar:
            clouds = simulate.scans(
                scene,
                sensor,
                poses,
                args.seed,
                noise,
                args.frame,
                organized=args.organized,
                on_scan=lambda i: bar.advance(1),
            )
        meta.update(preset=preset, rate_hz=sensor.rate, frame=args.frame)
    if str(args.out).endswith(".mcap"):
        if args.organized:
            raise ConfigError("--organized writes .npz or .ply files, not a recording")
        return _write_recording(args.out, clouds, meta, args.quiet)
    written = write_sim_clouds(args.out, clouds, meta)
    for i, path in enumerate(written):
        if not args.quiet:
            print(f"{path} ({len(clouds[i])} points)" if i < len(clouds) else path)
    return 0


def _check_sensor_args(args: argparse.Namespace, noise: NoiseSpec) -> None:
    """Raise ConfigError for options that do not go with ``--sensor`` (or out of range)."""
    from supportnode.errors import ConfigError

    if args.sensor == "sample":
        if args.points < 1:
            raise ConfigError(f"--points must be at least 1, got {args.points}")
        if args.preset is not None or args.frames != 1 or args.frame != "world":
            raise ConfigError("--preset, --frames and --frame apply to --sensor lidar or camera")
        if noise.range > 0:
            raise ConfigError("range noise follows sensor rays: use --sensor lidar or camera")
    if args.sensor != "camera" and (noise.kinect > 0 or args.organized or args.frame == "optical"):
        raise ConfigError("kinect noise, --organized and --frame optical need --sensor camera")
    if args.sensor != "sample" and args.frames < 1:
        raise ConfigError(f"--frames must be at least 1, got {args.frames}")


def _sensor(args: argparse.Namespace) -> tuple[str, Lidar | DepthCamera]:
    """The preset's name and the simulated sensor of ``--sensor lidar|camera --preset``."""
    from supportnode.errors import ConfigError
    from supportnode.sim.sensors import DepthCamera, Lidar

    if args.sensor == "lidar":
        preset = args.preset or "vlp16"
        if preset not in LIDAR_PRESETS:
            raise ConfigError(f"--preset {preset} is a camera preset; lidar: vlp16, os128")
        return preset, Lidar.preset(preset)
    preset = args.preset or "vga"
    if preset not in CAMERA_PRESETS:
        raise ConfigError(f"--preset {preset} is a lidar preset; camera: d435, vga")
    return preset, DepthCamera.preset(preset)


def _write_recording(out: str, clouds: list, meta: dict, quiet: bool) -> int:
    """A recording `supportnode play` replays: the frames as PointCloud messages on topic
    `scan`, in the sensor frame with the sensor pose (as a driver sends them), 1/rate apart;
    written through the same conversion as `supportnode record --from FOLDER`."""
    import tempfile
    from pathlib import Path

    from supportnode.io.recording import RecordingWriter
    from supportnode.io.sources import open_source
    from supportnode.sim.files import write_sim_clouds

    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        write_sim_clouds(tmp, clouds, meta)
        with (
            open_source(tmp, topic="scan") as src,
            RecordingWriter(out, metadata={k: str(v) for k, v in meta.items()}) as writer,
        ):
            for m in src.messages():
                writer.write(m.frames, receive_time=m.time)
    if not quiet:
        print(f"{out} ({len(clouds)} scans on topic scan)")
    return 0
