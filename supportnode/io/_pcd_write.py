"""PCD (PCL Point Cloud Data, v0.7) writing: ascii, binary, binary_compressed (LZF)."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np

from supportnode.errors import CloudFormatError
from supportnode.io import _lzf
from supportnode.io._pcd import DATA_KINDS

__all__ = ["write_pcd"]

_KIND_TO_TYPE = {"f": "F", "u": "U", "i": "I", "b": "U"}


def write_pcd(
    path: Path, xyz: np.ndarray, fields: dict[str, np.ndarray], data: str, name: str
) -> None:
    """Write validated arrays to a PCD v0.7 file (fields: (N,) or (N, k), rgb (N, 3) uint8)."""
    if data not in DATA_KINDS:
        raise CloudFormatError(
            f"{name}: unknown PCD data kind {data!r} (expected ascii, binary or binary_compressed)"
        )
    n = xyz.shape[0]
    columns = _columns(xyz, fields, name)
    with open(path, "wb") as fh:
        fh.write(_header(columns, n, data).encode("ascii"))
        if data == "ascii":
            _write_ascii(fh, columns, n)
        elif data == "binary":
            dt = np.dtype(
                [(f"{i}", "<" + a.dtype.str[1:], a.shape[1:]) for i, (_, a) in enumerate(columns)]
            )
            rec = np.empty(n, dtype=dt)
            for i, (_, a) in enumerate(columns):
                rec[f"{i}"] = a
            fh.write(rec.tobytes())
        else:
            blob = b"".join(
                np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes()
                for _, a in columns
            )
            comp = _lzf.compress_literal(blob)
            fh.write(struct.pack("<II", len(comp), len(blob)))
            fh.write(comp)


def _columns(
    xyz: np.ndarray, fields: dict[str, np.ndarray], name: str
) -> list[tuple[str, np.ndarray]]:
    """The file's columns: x, y, z, then each field as PCD can hold it (rgb packed in a float32,
    booleans as uint8, half floats widened); raises CloudFormatError for one it cannot."""
    n = xyz.shape[0]
    columns: list[tuple[str, np.ndarray]] = [("x", xyz[:, 0]), ("y", xyz[:, 1]), ("z", xyz[:, 2])]
    for fname, arr in fields.items():
        if fname == "rgb" and arr.shape == (n, 3):
            packed = (
                (arr[:, 0].astype(np.uint32) << 16)
                | (arr[:, 1].astype(np.uint32) << 8)
                | arr[:, 2].astype(np.uint32)
            )
            # PCL stores packed colour in a float32 field; in ascii it prints the uint32 value
            columns.append(("rgb", packed.view(np.float32)))
            continue
        if not fname or any(ch.isspace() for ch in fname) or fname in ("x", "y", "z"):
            raise CloudFormatError(f"{name}: field name {fname!r} cannot be written to PCD")
        if arr.dtype == np.bool_:
            arr = arr.astype(np.uint8)
        if arr.dtype.kind not in "fui" or arr.dtype.itemsize not in (1, 2, 4, 8):
            raise CloudFormatError(f"{name}: field {fname!r} has dtype {arr.dtype}, not numeric")
        if arr.dtype.kind == "f" and arr.dtype.itemsize < 4:
            arr = arr.astype(np.float32)
        columns.append((fname, arr))
    return columns


def _header(columns: list[tuple[str, np.ndarray]], n: int, data: str) -> str:
    """The PCD v0.7 header of ``n`` points in ``columns``, stored as ``data``."""
    names = [c[0] for c in columns]
    types = [_KIND_TO_TYPE[a.dtype.kind] for _, a in columns]
    sizes = [a.dtype.itemsize for _, a in columns]
    counts = [1 if a.ndim == 1 else a.shape[1] for _, a in columns]
    return (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\n"
        f"FIELDS {' '.join(names)}\n"
        f"SIZE {' '.join(map(str, sizes))}\n"
        f"TYPE {' '.join(types)}\n"
        f"COUNT {' '.join(map(str, counts))}\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )


def _write_ascii(fh: Any, columns: list[tuple[str, np.ndarray]], n: int) -> None:
    blocks: list[np.ndarray] = []
    fmts: list[str] = []
    for fname, a in columns:
        a2 = a.reshape(n, -1)
        if fname == "rgb" and a.dtype == np.float32:
            a2 = a2.view(np.uint32)
        if a2.dtype.kind in "ui":
            # via object-free int64/uint64 text: integers print exactly
            fmt = "%d"
            a2 = a2.astype(np.uint64 if a2.dtype.kind == "u" else np.int64)
        else:
            fmt = "%.9g" if a2.dtype.itemsize == 4 else "%.17g"
        blocks.append(a2)
        fmts.extend([fmt] * a2.shape[1])
    if n == 0:
        return
    # savetxt on a structured table keeps 64-bit integers exact (no float64 detour)
    flat = [b[:, k] for b in blocks for k in range(b.shape[1])]
    table = np.empty(n, dtype=[(f"c{j}", c.dtype) for j, c in enumerate(flat)])
    for j, c in enumerate(flat):
        table[f"c{j}"] = c
    np.savetxt(fh, table, fmt=" ".join(fmts))
