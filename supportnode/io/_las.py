"""LAS / LAZ point clouds through laspy (the ``las`` extra; lazrs decompresses LAZ).

Survey coordinates are large (UTM eastings ~ 5e5 m, northings ~ 5e6 m): float32 keeps only
about 6 cm of them, and a voxel hash of them wastes its bits. The reader subtracts an origin,
the scaled header offset rounded down to a whole metre (or the points' minimum when the offset
is zero or far outside them), so the cloud is local; the origin is reported with the results.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from supportnode.errors import CloudFormatError
from supportnode.io._common import RawCloud

INSTALL_HINT = "install the LAS extra: pip install 'supportnode[las]' (laspy and lazrs)"
# An offset farther than this from the points is not theirs (a default 0, or a typo).
_OFFSET_SLACK_M = 1e4
# Point-format dimensions worth keeping as fields (when present).
_FIELDS = ("intensity", "classification", "return_number", "number_of_returns", "gps_time")


def read_las(path: Path, name: str) -> RawCloud:
    """Rows of a .las/.laz file: xyz minus ``origin`` (metres, float64), colours, fields."""
    try:
        import laspy
    except ImportError as err:
        raise CloudFormatError(f"{name}: reading LAS/LAZ needs laspy: {INSTALL_HINT}") from err
    try:
        las = laspy.read(path)
    except laspy.errors.LaspyException as err:
        text = str(err)
        if "lazrs" in text.lower() or ("laz" in text.lower() and "backend" in text.lower()):
            raise CloudFormatError(f"{name}: LAZ needs a decompressor: {INSTALL_HINT}") from err
        raise CloudFormatError(f"{name}: not a readable LAS file ({text})") from err
    except (ValueError, EOFError) as err:
        raise CloudFormatError(f"{name}: not a readable LAS file ({err})") from err
    scale = np.asarray(las.header.scales, dtype=np.float64)
    offset = np.asarray(las.header.offsets, dtype=np.float64)
    raw = np.stack([np.asarray(las.X), np.asarray(las.Y), np.asarray(las.Z)], axis=1)
    origin = _origin(raw, scale, offset)
    # integer counts times scale, plus what the offset adds beyond the origin: exact in float64
    xyz = raw.astype(np.float64) * scale + (offset - origin)
    fields = {}
    dims = set(las.point_format.dimension_names)
    for key in _FIELDS:
        if key in dims:
            fields[key] = np.asarray(las[key]).astype(np.float64 if key == "gps_time" else np.int32)
    if {"red", "green", "blue"} <= dims:
        rgb = np.stack([np.asarray(las.red), np.asarray(las.green), np.asarray(las.blue)], 1)
        fields["rgb"] = (
            (rgb >> 8).astype(np.uint8) if rgb.max(initial=0) > 255 else rgb.astype(np.uint8)
        )
    return RawCloud(xyz, fields, origin=origin)


def _origin(raw: np.ndarray, scale: np.ndarray, offset: np.ndarray) -> np.ndarray:
    if len(raw) == 0:
        return np.zeros(3)
    lo = raw.min(axis=0) * scale + offset
    hi = raw.max(axis=0) * scale + offset
    inside = np.all((offset >= lo - _OFFSET_SLACK_M) & (offset <= hi + _OFFSET_SLACK_M))
    base = offset if inside and np.any(offset != 0) else lo
    out: np.ndarray = np.floor(base)
    return out
