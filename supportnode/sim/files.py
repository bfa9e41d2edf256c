"""Simulated clouds on disk: PLY (x y z + role primitive object surface supported_by
support_surface) and NPZ (everything).

NPZ keys: points (N, 3) float32, role (N,) int8, primitive / object / surface / supported_by /
support_surface (N,) int32 (see `SimCloud`),
sensor_pose (4, 4) float64, stamp () float64, tilt_rotation (3, 3) float64, frame () str, and
image_shape (2,) (rows, columns) for an organised cloud (NaN rows where a pixel saw nothing).
Several frames go to ``name_000.ext``, ``name_001.ext``... (a file path) or ``frame_000.npz``...
(a directory), with a JSON of poses and stamps next to them.
"""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from supportnode.errors import CloudFormatError
from supportnode.io.clouds import write_ply
from supportnode.sim.cloud import SimCloud

EXTENSIONS = (".ply", ".npz")


def write_sim_cloud(path: str | Path, cloud: SimCloud) -> Path:
    """Write one cloud as binary PLY with ground-truth properties, or as NPZ; returns the path."""
    path = Path(path)
    if path.suffix == ".ply":
        fields = {
            "role": cloud.role,
            "primitive": cloud.primitive,
            "object": cloud.object,
            "surface": cloud.surface,
            "supported_by": cloud.supported_by,
            "support_surface": cloud.support_surface,
        }
        write_ply(path, cloud.points.astype(np.float32, copy=False), fields=fields)
    elif path.suffix == ".npz":
        try:
            _write_npz(path, cloud.arrays())
        except OSError as err:
            raise CloudFormatError(f"{path}: cannot write ({err.strerror or err})") from err
    else:
        raise CloudFormatError(f"{path}: expected a .ply or .npz file name")
    return path


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Like np.savez_compressed, but with a fixed timestamp on every member so the same cloud
    always gives the same bytes (regenerated sim_scans/ then show no spurious git changes)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for key, value in arrays.items():
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            with zf.open(info, "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(value), allow_pickle=False)


def read_sim_npz(path: str | Path) -> SimCloud:
    """A SimCloud from an NPZ written by `write_sim_cloud`."""
    try:
        with np.load(path) as z:
            # Files from before the support labels: support unknown, read as none.
            none = np.full(len(z["object"]), -1, np.int32)
            return SimCloud(
                points=z["points"],
                role=z["role"],
                primitive=z["primitive"],
                object=z["object"],
                surface=z["surface"],
                supported_by=z["supported_by"] if "supported_by" in z else none,
                support_surface=z["support_surface"] if "support_surface" in z else none,
                sensor_pose=z["sensor_pose"],
                stamp=float(z["stamp"]),
                tilt_rotation=z["tilt_rotation"] if "tilt_rotation" in z else np.eye(3),
                frame=str(z["frame"]) if "frame" in z else "world",
                image_shape=_image_shape(z),
            )
    except (OSError, KeyError, ValueError) as err:
        raise CloudFormatError(f"{path}: not a simulator NPZ ({err})") from err


def _image_shape(z: Any) -> tuple[int, int] | None:
    """(rows, columns) of an organised cloud's NPZ, None for an unorganised one."""
    if "image_shape" not in z:
        return None
    rows, cols = (int(v) for v in z["image_shape"])
    return rows, cols


def output_paths(out: str | Path, count: int) -> tuple[list[Path], Path | None]:
    """File names for `count` clouds and, for several frames or a directory, the trajectory
    JSON. A .ply/.npz path names one file or a numbered series; anything else is a directory
    of frame_NNN.npz."""
    out = Path(out)
    if out.suffix in EXTENSIONS:
        if count == 1:
            return [out], None
        files = [out.with_name(f"{out.stem}_{i:03d}{out.suffix}") for i in range(count)]
        return files, out.with_name(f"{out.stem}_trajectory.json")
    if out.suffix:
        raise CloudFormatError(f"{out}: expected a .ply or .npz file or a directory")
    return [out / f"frame_{i:03d}.npz" for i in range(count)], out / "trajectory.json"


def write_sim_clouds(
    out: str | Path, clouds: list[SimCloud], meta: dict[str, Any] | None = None
) -> list[Path]:
    """Write `clouds` to `out` (see `output_paths`); returns every file written, JSON last.

    The JSON holds `meta` (scene, sensor, noise, seed: what made the files) and per frame the
    file name, stamp (s), sensor_pose (4x4, sensor-to-world) and tilt_rotation (3x3).
    """
    files, traj = output_paths(out, len(clouds))
    files[0].parent.mkdir(parents=True, exist_ok=True)
    written = [write_sim_cloud(f, c) for f, c in zip(files, clouds, strict=True)]
    if traj is not None:
        frames = [
            {
                "file": f.name,
                "stamp": c.stamp,
                "frame": c.frame,
                "points": len(c),
                "sensor_pose": np.round(c.sensor_pose, 9).tolist(),
                "tilt_rotation": np.round(c.tilt_rotation, 9).tolist(),
            }
            for f, c in zip(files, clouds, strict=True)
        ]
        text = json.dumps({**(meta or {}), "frames": frames}, indent=1)
        # Innermost lists (matrix rows, noise specs) on one line each keep the file readable.
        text = re.sub(r"\[[^\[\]{}]*\]", lambda m: json.dumps(json.loads(m.group(0))), text)
        traj.write_text(text + "\n")
        written.append(traj)
    return written
