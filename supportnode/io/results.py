"""Writing a detection to a folder: the report's clouds, result.json, labels.npz, one PLY per
object. The files a user opens after `supportnode detect`."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, cast

import numpy as np

from supportnode.errors import CloudFormatError
from supportnode.io.clouds import Cloud, write_ply
from supportnode.pipeline import Detection

RED = np.array([255, 0, 0], dtype=np.uint8)
GREEN = np.array([0, 255, 0], dtype=np.uint8)


def per_input_row(labels: np.ndarray, cloud: Cloud) -> np.ndarray:
    """Spread (N,) labels of the kept points over the file's rows: (input_count,) int32, -1 on
    rows dropped for NaN/Inf, so labels line up with the input file row by row."""
    out = np.full(cloud.input_count, -1, dtype=np.int32)
    out[cloud.source_index] = labels
    return out


def _write_objects(obj_dir: Path, points: np.ndarray, labels: np.ndarray, count: int) -> list[Path]:
    """One PLY per object id 0..count-1 (``000.ply`` ...: the points labelled with it)."""
    obj_dir.mkdir(exist_ok=True)
    for stale in obj_dir.glob("*.ply"):  # a rerun with fewer objects leaves none behind
        stale.unlink()
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(count + 1))
    written = []
    for cid in range(count):  # one file per object
        path = obj_dir / f"{cid:03d}.ply"
        write_ply(path, points[order[bounds[cid] : bounds[cid + 1]]])
        written.append(path)
    return written


def write_detection(
    out_dir: str | os.PathLike[str],
    name: str,
    cloud: Cloud,
    points: np.ndarray,
    detection: Detection,
    params_dict: dict[str, Any],
    extra: dict[str, Any] | None = None,
) -> list[Path]:
    """Write every output of one detection; returns the paths written.

    points: (N, 3) float64 in the detection frame (aligned when gravity alignment ran)."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise CloudFormatError(f"{out}: cannot create output folder: {err.strerror}") from err
    written: list[Path] = []
    on = detection.surfaces.labels >= 0
    for suffix, mask, colour in (("detected", on, RED), ("not_detected", ~on, GREEN)):
        path = out / f"{name}_{suffix}.ply"
        sel = points[mask]
        write_ply(path, sel, colors=np.broadcast_to(colour, (len(sel), 3)).copy())
        written.append(path)

    finite = np.zeros(cloud.input_count, dtype=bool)
    finite[cloud.source_index] = True  # the rows the clouds above hold, in this order
    arrays = {"surface": per_input_row(detection.surfaces.labels, cloud), "finite": finite}
    if detection.objects is not None:
        arrays["object"] = per_input_row(detection.objects.labels, cloud)
        objects = detection.objects
        obj_dir = out / f"{name}_objects"
        written += _write_objects(obj_dir, points, objects.labels, len(objects.clusters))
    labels_path = out / "labels.npz"
    # Any: numpy's stub reads a ** mapping as possibly holding its allow_pickle flag.
    np.savez_compressed(labels_path, **cast("dict[str, Any]", arrays))
    written.append(labels_path)

    result = {
        "input": {
            "path": str(cloud.path),
            "rows": int(cloud.input_count),
            "points": len(points),
            "dropped_nonfinite": int(cloud.dropped_nonfinite),
            # metres subtracted from the file's coordinates (LAS/LAZ survey coordinates):
            # add it to every position in this file to get the file's frame back
            "origin": None if cloud.origin is None else [float(v) for v in cloud.origin],
        },
        "params": params_dict,
        **(extra or {}),
        **detection.to_dict(),
    }
    result_path = out / "result.json"
    result_path.write_text(json.dumps(result, indent=1) + "\n")
    written.append(result_path)
    return written
