"""Point-cloud files: read PLY, PCD, XYZ/TXT/CSV, NPY/NPZ, OBJ and LAS/LAZ; write PLY, PCD, NPY
and NPZ.

Every reader returns a :class:`Cloud` whose points are finite (N, 3) float64 in the file's own
units (the library never rescales; e.g. some time-of-flight PCDs are in millimetres); LAS/LAZ
survey coordinates are made local by subtracting ``origin``. Rows with a
NaN/Inf coordinate are dropped and counted; ``source_index`` maps kept rows back to the file.
Any problem with a file raises :class:`~supportnode.errors.CloudFormatError` with a one-line
message that starts with the path.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from supportnode.errors import CloudFormatError
from supportnode.io import _las, _pcd, _pcd_write, _ply, _text
from supportnode.io._common import RawCloud, combine_rgb, to_uint8_colour

__all__ = ["Cloud", "read_cloud", "write_cloud", "write_pcd", "write_ply"]

READ_EXTENSIONS = (".ply", ".pcd", ".xyz", ".txt", ".csv", ".npy", ".npz", ".obj", ".las", ".laz")
WRITE_EXTENSIONS = (".ply", ".pcd", ".npy", ".npz")


@dataclass
class Cloud:
    """Finite points of a cloud file with their per-point properties.

    ``points`` is (N, 3) float64 in the file's units (metres for our data); every array in
    ``fields`` has N rows, (N,) or (N, k) (``"rgb"`` is (N, 3) uint8); ``source_index`` (N,)
    int64 is each point's row in the file (row-major pixel index for organised clouds);
    ``origin`` (3,) is what was subtracted from the file's coordinates (LAS/LAZ), else None.
    """

    points: np.ndarray
    fields: dict[str, np.ndarray]
    source_index: np.ndarray
    input_count: int
    dropped_nonfinite: int
    width: int | None = None
    height: int | None = None
    viewpoint: np.ndarray | None = None
    path: str = ""
    origin: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])


# ------------------------------------------------------------------------------------- reading


def read_cloud(path: str | os.PathLike[str], allow_empty: bool = False) -> Cloud:
    """Read a point cloud, choosing the format by extension (case-insensitive).

    allow_empty: a file without rows is a Cloud of 0 points (our outputs can be: nothing
    detected), not an error.

    Supported: .ply .pcd .xyz .txt .csv .npy .npz .obj .las .laz. Raises CloudFormatError on a missing,
    unreadable, malformed, truncated or empty file (including one whose points are all NaN/Inf).
    """
    name = os.fspath(path)
    p = Path(name)
    ext = p.suffix.lower()
    reader = _READERS.get(ext)
    if reader is None:
        raise CloudFormatError(
            f"{name}: unknown extension {p.suffix!r} (expected {' '.join(READ_EXTENSIONS)})"
        )
    if not p.exists():
        raise CloudFormatError(f"{name}: no such file")
    if p.is_dir():
        raise CloudFormatError(f"{name}: is a directory, not a file")
    try:
        raw = reader(p, name)
    except OSError as err:
        raise CloudFormatError(f"{name}: cannot read ({err.strerror or err})") from err
    except MemoryError as err:
        raise CloudFormatError(f"{name}: too large to load into memory") from err
    return _finish(raw, name, allow_empty)


def _finish(raw: RawCloud, name: str, allow_empty: bool = False) -> Cloud:
    xyz = raw.xyz
    n = xyz.shape[0]
    if n == 0 and allow_empty:
        empty = np.zeros(0, np.int64)
        return Cloud(np.zeros((0, 3)), dict(raw.fields), empty, 0, 0, path=name)
    if n == 0:
        raise CloudFormatError(f"{name}: no points")
    finite = np.isfinite(xyz).all(axis=1)
    kept = int(np.count_nonzero(finite))
    if kept == 0:
        raise CloudFormatError(f"{name}: no finite points ({n} rows, all NaN/Inf)")
    fields = {}
    for key, arr in raw.fields.items():
        if arr.shape[0] != n:  # readers guarantee this; a guard against silent misalignment
            raise CloudFormatError(f"{name}: field {key!r} has {arr.shape[0]} rows, not {n}")
        fields[key] = arr if kept == n else arr[finite]
    return Cloud(
        points=np.ascontiguousarray(xyz if kept == n else xyz[finite], dtype=np.float64),
        fields=fields,
        source_index=np.flatnonzero(finite).astype(np.int64),
        input_count=n,
        dropped_nonfinite=n - kept,
        width=raw.width,
        height=raw.height,
        viewpoint=raw.viewpoint,
        path=name,
        origin=raw.origin,
    )


def _read_npy(path: Path, name: str) -> RawCloud:
    with open(path, "rb") as fh:
        if fh.read(6) != b"\x93NUMPY":
            raise CloudFormatError(f"{name}: not a .npy file (bad magic bytes)")
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, EOFError, zipfile.BadZipFile) as err:
        if "pickle" in str(err):
            raise CloudFormatError(f"{name}: holds Python objects, not a numeric array") from err
        raise CloudFormatError(f"{name}: not a valid .npy array ({_one_line(err)})") from err
    if not isinstance(arr, np.ndarray):
        raise CloudFormatError(f"{name}: not a .npy array")
    if arr.dtype.names:
        if arr.ndim != 1 or not all(c in arr.dtype.names for c in ("x", "y", "z")):
            raise CloudFormatError(
                f"{name}: structured array needs 1-D shape and x, y, z fields "
                f"(has {', '.join(arr.dtype.names)})"
            )
        xyz = np.column_stack([arr[c].astype(np.float64) for c in ("x", "y", "z")])
        fields = {k: np.ascontiguousarray(arr[k]) for k in arr.dtype.names if k not in "xyz"}
        return RawCloud(xyz=xyz.reshape(-1, 3), fields=combine_rgb(fields))
    if arr.ndim != 2 or arr.shape[1] < 3 or arr.dtype.kind not in "fiu":
        raise CloudFormatError(
            f"{name}: expected an (N, 3) numeric array or x/y/z records, got shape {arr.shape} "
            f"dtype {arr.dtype}"
        )
    fields = {f"col{i}": arr[:, i].copy() for i in range(3, arr.shape[1])}
    return RawCloud(xyz=arr[:, :3].astype(np.float64), fields=fields)


def _read_npz(path: Path, name: str) -> RawCloud:
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (ValueError, EOFError, zipfile.BadZipFile, KeyError) as err:
        raise CloudFormatError(f"{name}: not a valid .npz archive ({_one_line(err)})") from err
    except AttributeError as err:  # np.load returned a plain array: an .npy renamed .npz
        raise CloudFormatError(f"{name}: not an .npz archive") from err
    key = next((k for k in ("points", "xyz") if k in arrays), None)
    if key is not None:
        pts = arrays.pop(key)
        if pts.ndim != 2 or pts.shape[1] < 3 or pts.dtype.kind not in "fiu":
            raise CloudFormatError(
                f"{name}: {key!r} must be an (N, 3) numeric array, got shape {pts.shape}"
            )
        xyz = pts[:, :3].astype(np.float64)
    elif all(c in arrays for c in ("x", "y", "z")):
        cols = [arrays.pop(c) for c in ("x", "y", "z")]
        if any(c.ndim != 1 or c.shape != cols[0].shape or c.dtype.kind not in "fiu" for c in cols):
            raise CloudFormatError(
                f"{name}: 'x', 'y', 'z' must be numeric (N,) arrays of one length"
            )
        xyz = np.column_stack(cols).astype(np.float64)
    else:
        raise CloudFormatError(
            f"{name}: no 'points' (or 'xyz') array and no 'x', 'y', 'z' arrays "
            f"(keys: {', '.join(sorted(arrays)) or 'none'})"
        )
    n = xyz.shape[0]
    # arrays of another length (metadata such as a pose) are not per-point: leave them out
    fields = {k: v for k, v in arrays.items() if v.ndim in (1, 2) and v.shape[0] == n}
    if "rgb" not in fields and "colors" in fields and fields["colors"].shape == (n, 3):
        fields["rgb"] = to_uint8_colour(fields.pop("colors"))
    return RawCloud(xyz=xyz.reshape(-1, 3), fields=combine_rgb(fields))


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


_READERS: dict[str, Callable[[Path, str], RawCloud]] = {
    ".ply": _ply.read_ply,
    ".pcd": _pcd.read_pcd,
    ".xyz": _text.read_table,
    ".txt": _text.read_table,
    ".csv": _text.read_table,
    ".npy": _read_npy,
    ".npz": _read_npz,
    ".obj": _text.read_obj,
    ".las": _las.read_las,
    ".laz": _las.read_las,
}

# ------------------------------------------------------------------------------------- writing


def _check_points(points: np.ndarray, name: str) -> np.ndarray:
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.dtype.kind not in "fiu":
        raise CloudFormatError(
            f"{name}: points must be an (N, 3) numeric array, got shape {pts.shape} dtype {pts.dtype}"
        )
    # float32 stays float32 (PCL's usual layout); everything else is written as float64
    return pts if pts.dtype == np.float32 else pts.astype(np.float64, copy=False)


def _check_colors(colors: np.ndarray | None, n: int, name: str) -> np.ndarray | None:
    if colors is None:
        return None
    c = np.asarray(colors)
    if c.shape != (n, 3):
        raise CloudFormatError(f"{name}: colors must be ({n}, 3), got shape {c.shape}")
    return to_uint8_colour(c)


def _check_fields(
    fields: Mapping[str, np.ndarray] | None, n: int, name: str
) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for key, value in (fields or {}).items():
        arr = np.asarray(value)
        if arr.ndim not in (1, 2) or arr.shape[0] != n:
            raise CloudFormatError(
                f"{name}: field {key!r} must have {n} rows ((N,) or (N, k)), got shape {arr.shape}"
            )
        if arr.dtype.kind not in "fiub":
            raise CloudFormatError(f"{name}: field {key!r} has dtype {arr.dtype}, not numeric")
        out[key] = arr
    return out


def write_ply(
    path: str | os.PathLike[str],
    points: np.ndarray,
    colors: np.ndarray | None = None,
    fields: Mapping[str, np.ndarray] | None = None,
    binary: bool = True,
) -> None:
    """Write (N, 3) points as a PLY vertex element (binary little endian, or ascii).

    ``colors`` (N, 3) uint8 become red/green/blue (a ``fields["rgb"]`` (N, 3) is used the same
    way when ``colors`` is None). Other fields are extra properties keeping their dtype, except
    that bool becomes uint8 and 64-bit integers become 32-bit (an error if values do not fit);
    an (N, k) field becomes properties ``name_0 .. name_{k-1}``.
    """
    name = os.fspath(path)
    pts = _check_points(points, name)
    n = pts.shape[0]
    flds = _check_fields(fields, n, name)
    if colors is None and "rgb" in flds and flds["rgb"].shape == (n, 3):
        colors = flds.pop("rgb")
    _ply.write_ply(Path(name), pts, _check_colors(colors, n, name), flds, binary, name)


def write_pcd(
    path: str | os.PathLike[str],
    points: np.ndarray,
    fields: Mapping[str, np.ndarray] | None = None,
    data: str = "binary",
) -> None:
    """Write (N, 3) points as an unorganised PCD v0.7 file.

    ``data`` is "ascii", "binary" or "binary_compressed" (LZF, literal runs only). Fields keep
    their dtype ((N, k) arrays become COUNT k; bool becomes U 1); ``fields["rgb"]`` (N, 3) uint8
    is packed into PCL's float32 ``rgb`` field.
    """
    name = os.fspath(path)
    pts = _check_points(points, name)
    flds = _check_fields(fields, pts.shape[0], name)
    if "rgb" in flds and flds["rgb"].shape[1:] == (3,):
        flds["rgb"] = to_uint8_colour(flds["rgb"])
    try:
        _pcd_write.write_pcd(Path(name), pts, flds, data, name)
    except OSError as err:
        raise CloudFormatError(f"{name}: cannot write ({err.strerror or err})") from err


def write_cloud(
    path: str | os.PathLike[str],
    points: np.ndarray,
    colors: np.ndarray | None = None,
    fields: Mapping[str, np.ndarray] | None = None,
) -> None:
    """Write (N, 3) points (+ optional (N, 3) colours and fields), format by extension.

    .ply (binary), .pcd (binary), .npy (plain (N, 3) array, or records x, y, z, red, green,
    blue, fields when there is more than points) and .npz (``points``, ``rgb``, one array per
    field).
    """
    name = os.fspath(path)
    ext = Path(name).suffix.lower()
    if ext == ".ply":
        write_ply(path, points, colors=colors, fields=fields)
        return
    pts = _check_points(points, name)
    n = pts.shape[0]
    flds = _check_fields(fields, n, name)
    cols = _check_colors(colors, n, name)
    if cols is not None:
        flds["rgb"] = cols
    if ext == ".pcd":
        write_pcd(path, pts, fields=flds)
        return
    if ext not in WRITE_EXTENSIONS:
        raise CloudFormatError(
            f"{name}: unknown extension {Path(name).suffix!r} for writing "
            f"(expected {' '.join(WRITE_EXTENSIONS)})"
        )
    try:
        with open(name, "wb") as fh:
            if ext == ".npy":
                np.save(fh, _records(pts, flds, name), allow_pickle=False)
            else:
                if "points" in flds:
                    raise CloudFormatError(f"{name}: a field may not be called 'points'")
                # Any: numpy's stub reads a ** mapping as possibly holding its allow_pickle flag.
                np.savez(fh, points=pts, **cast("dict[str, Any]", flds))
    except OSError as err:
        raise CloudFormatError(f"{name}: cannot write ({err.strerror or err})") from err


def _records(pts: np.ndarray, flds: dict[str, np.ndarray], name: str) -> np.ndarray:
    if not flds:
        return pts
    columns: list[tuple[str, np.ndarray]] = [("x", pts[:, 0]), ("y", pts[:, 1]), ("z", pts[:, 2])]
    for key, arr in flds.items():
        if key == "rgb" and arr.shape[1:] == (3,):
            columns += [("red", arr[:, 0]), ("green", arr[:, 1]), ("blue", arr[:, 2])]
        elif key in ("x", "y", "z", "red", "green", "blue"):
            raise CloudFormatError(f"{name}: field name {key!r} clashes with a column")
        else:
            columns.append((key, arr))
    rec = np.empty(
        pts.shape[0],
        dtype=[(k, a.dtype, a.shape[1:]) if a.ndim == 2 else (k, a.dtype) for k, a in columns],
    )
    for k, a in columns:
        rec[k] = a
    return rec
