"""PCD (PCL Point Cloud Data, v0.6/v0.7) reading: ascii, binary, binary_compressed (writing:
`supportnode.io._pcd_write`)."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from supportnode.errors import CloudFormatError
from supportnode.io import _lzf
from supportnode.io._common import RawCloud, loadtxt_lines, split_rgb_packed

_TYPES = {
    ("F", 4): "f4",
    ("F", 8): "f8",
    ("U", 1): "u1",
    ("U", 2): "u2",
    ("U", 4): "u4",
    ("U", 8): "u8",
    ("I", 1): "i1",
    ("I", 2): "i2",
    ("I", 4): "i4",
    ("I", 8): "i8",
}
DATA_KINDS = ("ascii", "binary", "binary_compressed")
_KNOWN_KEYS: tuple[str, ...] = ("VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT")
_KNOWN_KEYS += ("WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


@dataclass
class _Header:
    names: list[str] = field(default_factory=list)
    sizes: list[int] = field(default_factory=list)
    types: list[str] = field(default_factory=list)
    counts: list[int] = field(default_factory=list)
    width: int | None = None
    height: int | None = None
    points: int | None = None
    viewpoint: np.ndarray | None = None
    data: str = ""
    body_offset: int = 0


def _ints(name: str, lineno: int, key: str, values: list[str]) -> list[int]:
    try:
        out = [int(v) for v in values]
    except ValueError as err:
        raise CloudFormatError(
            f"{name}: header line {lineno}: {key} must be "
            f"{'an integer' if key in ('WIDTH', 'HEIGHT', 'POINTS') else 'integers'}, "
            f"got {' '.join(values)!r}"
        ) from err
    if any(v < 0 for v in out):
        raise CloudFormatError(f"{name}: header line {lineno}: {key} must not be negative")
    return out


def _parse_header(raw: bytes, name: str) -> _Header:
    hdr = _Header()
    seen: dict[str, int] = {}
    pos = 0
    lineno = 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0:
            if pos >= len(raw):
                raise CloudFormatError(f"{name}: header has no DATA line")
            end = len(raw)
        lineno += 1
        line = raw[pos:end].decode("latin-1").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        key = key.upper()
        if key not in _KNOWN_KEYS:
            if lineno == 1 or not seen:
                raise CloudFormatError(f"{name}: not a PCD file (line {lineno}: {line[:40]!r})")
            raise CloudFormatError(f"{name}: header line {lineno}: unknown key {key!r}")
        seen[key] = lineno
        if key in ("FIELDS", "COLUMNS"):
            hdr.names = vals
        elif key == "SIZE":
            hdr.sizes = _ints(name, lineno, key, vals)
        elif key == "TYPE":
            hdr.types = [v.upper() for v in vals]
        elif key == "COUNT":
            hdr.counts = _ints(name, lineno, key, vals)
        elif key in ("WIDTH", "HEIGHT", "POINTS"):
            if len(vals) != 1:
                raise CloudFormatError(f"{name}: header line {lineno}: {key} needs one integer")
            setattr(hdr, key.lower(), _ints(name, lineno, key, vals)[0])
        elif key == "VIEWPOINT":
            try:
                vp = np.array([float(v) for v in vals], dtype=np.float64)
            except ValueError as err:
                raise CloudFormatError(f"{name}: header line {lineno}: bad VIEWPOINT") from err
            if vp.shape != (7,):
                raise CloudFormatError(f"{name}: header line {lineno}: VIEWPOINT needs 7 numbers")
            hdr.viewpoint = vp
        elif key == "DATA":
            kind = vals[0].lower() if vals else ""
            if kind not in DATA_KINDS:
                raise CloudFormatError(
                    f"{name}: header line {lineno}: unknown DATA kind {kind!r} "
                    f"(expected ascii, binary or binary_compressed)"
                )
            hdr.data = kind
            hdr.body_offset = min(pos, len(raw))
            break
    _check_header(hdr, seen, name)
    return hdr


def _check_header(hdr: _Header, seen: dict[str, int], name: str) -> None:
    if not hdr.names:
        raise CloudFormatError(f"{name}: header has no FIELDS line")
    n = len(hdr.names)
    if not hdr.counts:
        hdr.counts = [1] * n
    if not hdr.sizes and hdr.data == "ascii":
        # v0.6 ascii files may omit SIZE/TYPE: treat every column as float64
        hdr.sizes, hdr.types = [8] * n, ["F"] * n
    for key, vals in (("SIZE", hdr.sizes), ("TYPE", hdr.types), ("COUNT", hdr.counts)):
        if not vals:
            raise CloudFormatError(f"{name}: header has no {key} line")
        if len(vals) != n:
            raise CloudFormatError(
                f"{name}: header line {seen[key]}: FIELDS and {key} counts differ "
                f"({n} fields, {len(vals)} {key} values)"
            )
    for fname, t, s in zip(hdr.names, hdr.types, hdr.sizes, strict=True):
        if (t, s) not in _TYPES:
            raise CloudFormatError(
                f"{name}: header line {seen['TYPE']}: field {fname!r} has unsupported "
                f"TYPE {t} SIZE {s}"
            )
    if "x" not in hdr.names or "y" not in hdr.names or "z" not in hdr.names:
        raise CloudFormatError(f"{name}: FIELDS has no x, y, z ({' '.join(hdr.names)})")
    if hdr.width is None:
        if hdr.points is None:
            raise CloudFormatError(f"{name}: header has neither WIDTH nor POINTS")
        hdr.width, hdr.height = hdr.points, 1
    if hdr.height is None:
        hdr.height = 1
    if hdr.points is None:
        hdr.points = hdr.width * hdr.height
    elif hdr.points != hdr.width * hdr.height:
        raise CloudFormatError(
            f"{name}: POINTS {hdr.points} differs from WIDTH x HEIGHT ({hdr.width} x {hdr.height})"
        )


def _dtype(hdr: _Header, keep_padding: bool = True) -> np.dtype:
    parts: list[tuple[Any, ...]] = []
    for i, (fname, t, s, c) in enumerate(
        zip(hdr.names, hdr.types, hdr.sizes, hdr.counts, strict=True)
    ):
        if fname == "_" and not keep_padding:
            continue
        # unique names so repeated padding fields (or duplicates) do not collide
        key = f"{i}:{fname}"
        base = "<" + _TYPES[(t, s)]
        parts.append((key, base, (c,)) if c != 1 else (key, base))
    return np.dtype(parts)


def read_pcd(path: Path, name: str) -> RawCloud:
    """Read a PCD file into raw columns (not yet filtered for NaN)."""
    raw = path.read_bytes()
    hdr = _parse_header(raw, name)
    n = hdr.points or 0
    body = memoryview(raw)[hdr.body_offset :]
    if hdr.data == "ascii":
        columns = _read_ascii(body, hdr, name)
    elif hdr.data == "binary":
        dt = _dtype(hdr)
        need = n * dt.itemsize
        if len(body) < need:
            raise CloudFormatError(
                f"{name}: truncated binary data: expected {need} bytes, found {len(body)}"
            )
        rec = np.frombuffer(body, dtype=dt, count=n)
        columns = {k: rec[k] for k in dt.names or ()}
    else:
        columns = _read_compressed(body, hdr, name)
    fields: dict[str, np.ndarray] = {}
    for key, col in columns.items():
        fname = key.split(":", 1)[1]
        if fname == "_":
            continue
        if fname in ("rgb", "rgba") and col.ndim == 1 and col.dtype.itemsize == 4:
            if col.dtype.kind != "f" or _looks_packed(col):
                fields["rgb"] = split_rgb_packed(col)
                continue
            # a float "rgb" that is not a packed colour (e.g. SICK stores intensity there)
            fname = f"{fname}_float"
        if fname in fields:
            raise CloudFormatError(f"{name}: field {fname!r} appears twice in FIELDS")
        # native byte order and an owned copy (the buffer is the whole file)
        fields[fname] = np.ascontiguousarray(col, dtype=col.dtype.newbyteorder("="))
    xyz = np.column_stack(
        [fields.pop(c).astype(np.float64, copy=False) for c in ("x", "y", "z")]
    ).reshape(n, 3)
    organised = hdr.height is not None and hdr.height > 1
    return RawCloud(
        xyz=xyz,
        fields=fields,
        width=hdr.width if organised else None,
        height=hdr.height if organised else None,
        viewpoint=hdr.viewpoint,
    )


def _looks_packed(col: np.ndarray) -> bool:
    """True if a float32 column holds 0xAARRGGBB bit patterns with alpha 0 or 255.

    Real packed colours have alpha 0 (tiny denormal floats) or 255 (NaN/huge); any other top
    byte means the column holds ordinary numbers.
    """
    top = np.ascontiguousarray(col, dtype=col.dtype.newbyteorder("=")).view(np.uint32) >> 24
    return bool(np.all((top == 0) | (top == 255)))


def _read_ascii(body: memoryview, hdr: _Header, name: str) -> dict[str, np.ndarray]:
    n = hdr.points or 0
    n_cols = sum(hdr.counts)
    header_lines = bytes(memoryview(body.obj)[: hdr.body_offset]).count(b"\n")  # type: ignore[arg-type]
    text = bytes(body).decode("latin-1")
    table = loadtxt_lines(text, name, first_line=header_lines + 1, n_cols=n_cols)
    if table.shape[0] < n:
        raise CloudFormatError(
            f"{name}: truncated ascii data: expected {n} points, found {table.shape[0]}"
        )
    table = table[:n]
    out: dict[str, np.ndarray] = {}
    col = 0
    for i, (fname, t, s, c) in enumerate(
        zip(hdr.names, hdr.types, hdr.sizes, hdr.counts, strict=True)
    ):
        block = table[:, col : col + c]
        col += c
        dt = np.dtype(_TYPES[(t, s)])
        if fname in ("rgb", "rgba") and c == 1 and s == 4:
            # PCL writes packed colour as its uint32 value; other tools print the float whose
            # bits hold it (a tiny denormal). Accept both, per value.
            v = block[:, 0]
            as_bits = (np.abs(v) < 1.0) & (v != 0)
            packed = np.where(as_bits, 0, np.nan_to_num(v)).astype(np.uint64).astype(np.uint32)
            packed[as_bits] = v[as_bits].astype(np.float32).view(np.uint32)
            out[f"{i}:{fname}"] = packed.view(np.float32) if t == "F" else packed
            continue
        if dt.kind in "iu":
            finite = np.isfinite(block)
            if not finite.all() or np.any(block != np.round(block)):
                raise CloudFormatError(
                    f"{name}: ascii data: field {fname!r} (TYPE {t}) holds non-integer values"
                )
        vals = block.astype(dt)
        out[f"{i}:{fname}"] = vals[:, 0] if c == 1 else vals
    return out


def _read_compressed(body: memoryview, hdr: _Header, name: str) -> dict[str, np.ndarray]:
    n = hdr.points or 0
    if len(body) < 8:
        raise CloudFormatError(
            f"{name}: truncated binary_compressed data: expected 8 header bytes, found {len(body)}"
        )
    csize, usize = struct.unpack("<II", body[:8])
    if len(body) - 8 < csize:
        raise CloudFormatError(
            f"{name}: truncated binary_compressed data: expected {csize} compressed bytes, "
            f"found {len(body) - 8}"
        )
    # PCL leaves padding fields ("_") out of compressed data; accept either layout
    dt = _dtype(hdr, keep_padding=False)
    if usize != n * dt.itemsize:
        dt_pad = _dtype(hdr, keep_padding=True)
        if usize != n * dt_pad.itemsize:
            raise CloudFormatError(
                f"{name}: binary_compressed size mismatch: header gives {n} points of "
                f"{dt.itemsize} bytes ({n * dt.itemsize}), compressed block says {usize}"
            )
        dt = dt_pad
    if n == 0:
        return {k: np.zeros((0, *dt[k].shape), dt[k].base) for k in dt.names or ()}
    try:
        buf = _lzf.decompress(body[8 : 8 + csize], usize)
    except _lzf.LZFError as err:
        raise CloudFormatError(f"{name}: binary_compressed data: {err}") from err
    # column-wise: all of field 0 for every point, then all of field 1, ...
    out: dict[str, np.ndarray] = {}
    offset = 0
    for key in dt.names or ():
        sub = dt[key]
        col = np.frombuffer(
            buf, dtype=sub.base, count=n * max(1, math.prod(sub.shape)), offset=offset
        )
        offset += n * sub.itemsize
        out[key] = col.reshape(n, *sub.shape) if sub.shape else col
    return out
