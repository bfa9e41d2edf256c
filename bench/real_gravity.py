"""Gravity alignment on the real scans beside the repository: refusals, level, time.

    python bench/real_gravity.py [--real ../shared/real_scans] [--repeat 3] [--timing mosd|sim]

Every scan as `supportnode detect SCAN --align` takes it: no hint, the camera at the origin,
the SICK scan in millimetres read with its guessed unit. Per scan: refused or not; `up err`,
the angle between the estimated up and the normal of the plane fitted to the points labelled
table (mOSD scans only, their ground truth); the tilt from +z of the detected floor or table
surfaces' normals (what result.json reports; `tests/real_levels.py` says which surface is the
floor or table); gravity ms, the median of --repeat runs. --timing mosd: only the mOSD
scans' gravity time and refusals; --timing sim: the simulator's scenes, 200,000 points tilted
by 20/15 deg, for a peer of the real scans in time. Both use nothing but the public API, so
that they run on any revision:

    cp bench/real_gravity.py /tmp/rg.py && python bench/ab.py --a main -- /tmp/rg.py --timing mosd

The last line is a JSON summary (for bench/ab.py).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from supportnode.errors import AlignmentError
from supportnode.geometry.gravity import estimate_gravity
from supportnode.io.clouds import read_cloud

REAL = Path(__file__).resolve().parent.parent.parent / "shared" / "real_scans"


def labelled_table_normal(cloud) -> np.ndarray:
    """Unit normal (3,) toward the camera of the plane through the points labelled table."""
    label = cloud.fields["label"].reshape(-1)
    q = cloud.points[(label >= 1) & (label <= 9)]
    for _ in range(3):  # drop the few labelled points off the plane (edges, mixed pixels)
        c = q.mean(axis=0)
        n = np.linalg.eigh((q - c).T @ (q - c))[1][:, 0]
        q = q[np.abs((q - c) @ n) < 0.015]
    return n if n @ c < 0 else -n


def timed(points: np.ndarray, repeat: int) -> tuple[object, float]:
    """(estimate or the AlignmentError, median seconds of ``repeat`` runs)."""
    times, result = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        try:
            result = estimate_gravity(points)
        except AlignmentError as err:
            result = err
        times.append(time.perf_counter() - t)
    return result, statistics.median(times)


def timing(root: Path, repeat: int) -> dict:
    learn = sorted((root / "mosd_learn").glob("learn*.pcd"), key=lambda p: int(p.stem[5:]))
    estimate_gravity(read_cloud(learn[0]).points)  # compiled kernels loaded, not timed
    refused, ms = 0, []
    for path in learn:
        result, dt = timed(read_cloud(path).points, repeat)
        refused += isinstance(result, AlignmentError)
        ms.append(dt * 1000)
    return {"mosd_scans": len(learn), "refused": refused, "gravity_ms_p50": statistics.median(ms)}


def timing_sim(repeat: int) -> dict:
    from supportnode.sim.noise import apply_tilt
    from supportnode.sim.scene import bundled_scenes, load_scene
    from supportnode.sim.sensors import sample_scene

    out = {}
    for name in bundled_scenes():
        cloud = apply_tilt(sample_scene(load_scene(name), 200_000, seed=2), 20.0, 15.0)
        points = cloud.points.astype(np.float64)
        estimate_gravity(points)  # compiled kernels loaded, not timed
        out[f"sim_{name}_ms"] = timed(points, repeat)[1] * 1000
    return {**out, "gravity_ms_p50": statistics.median(out.values())}


def full(root: Path, repeat: int) -> dict:
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from common import table
    from real_levels import read_metres, scan_paths, supports

    from supportnode.pipeline import detect

    paths = scan_paths(root)
    estimate_gravity(read_metres(paths[0]).points)  # compiled kernels loaded, not timed
    rows, ms, errs, worst, refused = [], [], [], 0.0, 0
    for path in paths:
        cloud = read_metres(path)
        result, dt = timed(cloud.points, repeat)
        ms.append(dt * 1000)
        if isinstance(result, AlignmentError):
            refused += 1
            rows.append([path.name, "refused", "-", str(result)[:60], f"{dt * 1000:.0f}"])
            continue
        err = "-"
        if "label" in cloud.fields:
            e = float(np.degrees(np.arccos(min(1.0, result.up @ labelled_table_normal(cloud)))))
            errs.append(e)
            err = f"{e:.2f}"
        det = detect(cloud.points, align=True, objects=False, sensor_origin=np.zeros(3))
        found = supports(path, cloud, det)
        worst = max([worst, *(s.tilt_deg for s in found)])
        levels = ", ".join(f"{s.name} {s.height:.2f} m: {s.tilt_deg:.2f}" for s in found)
        rows.append([path.name, "aligned", err, levels, f"{dt * 1000:.0f}"])
    print(table(rows, ["scan", "gravity", "up err deg", "support: height, tilt deg", "ms"]))
    return {
        "scans": len(paths),
        "refused": refused,
        "mosd_up_err_deg_p50": statistics.median(errs),
        "mosd_up_err_deg_max": max(errs),
        "support_tilt_deg_max": worst,
        "gravity_ms_p50": statistics.median(ms),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", type=Path, default=REAL, help="the real_scans folder")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per scan")
    ap.add_argument("--timing", choices=("mosd", "sim"), help="gravity time only (any rev)")
    args = ap.parse_args()
    if args.timing == "sim":
        summary = timing_sim(args.repeat)
    elif not (args.real / "mosd_learn").is_dir():
        print(f"real_gravity.py: error: {args.real}/mosd_learn not found", file=sys.stderr)
        return 2
    else:
        summary = (timing if args.timing else full)(args.real, args.repeat)
    print(json.dumps({**summary, "load": os.getloadavg()[0]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
