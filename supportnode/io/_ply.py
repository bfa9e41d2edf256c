"""PLY reading and writing through ``plyfile`` (ascii, binary little and big endian)."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np
import plyfile

from supportnode.errors import CloudFormatError
from supportnode.io._common import RawCloud, combine_rgb

# dtypes PLY can hold; wider integers are narrowed when their values fit
_PLY_KINDS = {"i1", "u1", "i2", "u2", "i4", "u4", "f4", "f8"}


def read_ply(path: Path, name: str) -> RawCloud:
    """Read the vertex element of a PLY file (faces and other elements are ignored)."""
    try:
        with open(path, "rb") as fh:
            data = _read_binary_vertices(fh, name)
            if data is None:
                fh.seek(0)
                # mmap: plyfile's non-mmap binary path decodes row by row (seconds per 1e5 rows)
                data = plyfile.PlyData.read(fh, mmap="c")["vertex"].data
    except plyfile.PlyParseError as err:
        msg = _one_line(err)
        if "end-of-file" in msg:
            raise CloudFormatError(f"{name}: truncated data ({msg})") from err
        raise CloudFormatError(f"{name}: {msg}") from err
    except KeyError as err:
        raise CloudFormatError(f"{name}: no vertex element") from err
    except (ValueError, struct.error, UnicodeDecodeError, EOFError, IndexError) as err:
        # plyfile lets some malformed-input errors through unwrapped
        raise CloudFormatError(f"{name}: malformed PLY ({_one_line(err)})") from err
    return _vertex_to_raw(data, name)


def _read_binary_vertices(fh: BinaryIO, name: str) -> np.ndarray | None:
    """Fast path: a binary file whose first element is a list-free vertex element.

    Reads only those bytes (faces after them are never parsed). Returns None when the file
    needs plyfile's general reader.
    """
    parse_header = getattr(plyfile.PlyData, "_parse_header", None)
    if parse_header is None:  # pragma: no cover - plyfile internals changed
        return None
    header = parse_header(fh)
    if header.text or not header.elements or header.elements[0].name != "vertex":
        return None
    vertex = header.elements[0]
    if any(isinstance(p, plyfile.PlyListProperty) for p in vertex.properties):
        return None
    dtype = np.dtype(vertex.dtype(header.byte_order))
    need = vertex.count * dtype.itemsize
    buf = fh.read(need)
    if len(buf) < need:
        raise CloudFormatError(
            f"{name}: truncated binary data: expected {need} bytes of vertices, found {len(buf)}"
        )
    return np.frombuffer(buf, dtype=dtype, count=vertex.count)


def _vertex_to_raw(data: np.ndarray, name: str) -> RawCloud:
    names = data.dtype.names or ()
    missing = [c for c in ("x", "y", "z") if c not in names]
    if missing:
        raise CloudFormatError(f"{name}: vertex element has no {'/'.join(missing)} property")
    xyz = np.column_stack([np.asarray(data[c], dtype=np.float64) for c in ("x", "y", "z")])
    fields: dict[str, np.ndarray] = {}
    for prop in names:
        if prop in ("x", "y", "z"):
            continue
        col = data[prop]
        if col.dtype == object:
            # a list property: keep it only when every row has the same length
            lengths = {len(v) for v in col}
            if len(lengths) > 1:
                continue
            col = np.stack(list(col)) if len(col) else np.zeros((0, 0))
        fields[prop] = np.array(col, dtype=col.dtype.newbyteorder("="), copy=True)
    return RawCloud(xyz=xyz.reshape(-1, 3), fields=combine_rgb(fields))


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


def narrow_for_ply(fname: str, arr: np.ndarray, name: str) -> np.ndarray:
    """Return ``arr`` in a dtype PLY supports, or raise when that would change its values."""
    if arr.dtype == np.bool_:
        return arr.astype(np.uint8)
    key = arr.dtype.kind + str(arr.dtype.itemsize)
    if key in _PLY_KINDS:
        return arr
    if arr.dtype.kind in "iu" and arr.dtype.itemsize == 8:
        target = np.int32 if arr.dtype.kind == "i" else np.uint32
        info = np.iinfo(target)
        if arr.size == 0 or (arr.min() >= info.min and arr.max() <= info.max):
            return arr.astype(target)
        raise CloudFormatError(
            f"{name}: field {fname!r} ({arr.dtype}) has values outside 32 bits, which PLY cannot store"
        )
    if arr.dtype.kind == "f" and arr.dtype.itemsize == 2:
        return arr.astype(np.float32)
    raise CloudFormatError(f"{name}: field {fname!r} has dtype {arr.dtype}, which PLY cannot store")


def write_ply(
    path: Path,
    xyz: np.ndarray,
    colors: np.ndarray | None,
    fields: dict[str, np.ndarray],
    binary: bool,
    name: str,
) -> None:
    """Write validated arrays as a PLY vertex element; (N, k) fields become name_0..name_{k-1}."""
    n = xyz.shape[0]
    columns: list[tuple[str, np.ndarray]] = [("x", xyz[:, 0]), ("y", xyz[:, 1]), ("z", xyz[:, 2])]
    if colors is not None:
        columns += [("red", colors[:, 0]), ("green", colors[:, 1]), ("blue", colors[:, 2])]
    for fname, arr in fields.items():
        if not fname or any(ch.isspace() for ch in fname):
            raise CloudFormatError(f"{name}: field name {fname!r} cannot be written to PLY")
        arr = narrow_for_ply(fname, arr, name)
        if arr.ndim == 1:
            columns.append((fname, arr))
        else:
            columns += [(f"{fname}_{k}", arr[:, k]) for k in range(arr.shape[1])]
    seen: set[str] = set()
    for cname, _ in columns:
        if cname in seen:
            raise CloudFormatError(f"{name}: property {cname!r} would be written twice")
        seen.add(cname)
    rec = np.empty(n, dtype=[(c, "<" + a.dtype.str[1:]) for c, a in columns])
    for c, a in columns:
        rec[c] = a
    element = plyfile.PlyElement.describe(rec, "vertex")
    ply = plyfile.PlyData([element], text=not binary, byte_order="<")
    try:
        ply.write(str(path))
    except OSError as err:
        raise CloudFormatError(f"{name}: cannot write ({err.strerror or err})") from err
