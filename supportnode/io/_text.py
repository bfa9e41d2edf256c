"""Plain-text clouds: XYZ/TXT/CSV tables and OBJ vertex lines."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from supportnode.errors import CloudFormatError
from supportnode.io._common import RawCloud, combine_rgb, loadtxt_lines, to_uint8_colour


def _read_text(path: Path, name: str) -> str:
    raw = path.read_bytes()
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise CloudFormatError(
            f"{name}: not a text file (undecodable byte at offset {err.start})"
        ) from err


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def read_table(path: Path, name: str) -> RawCloud:
    """Read x y z [more columns] separated by whitespace or commas, with an optional name header."""
    text = _read_text(path, name)
    lines = text.split("\n")
    first = next(
        (i for i, ln in enumerate(lines) if ln.split("#", 1)[0].strip()),
        None,
    )
    if first is None:
        raise CloudFormatError(f"{name}: no points")
    head = lines[first].split("#", 1)[0].strip()
    delimiter = "," if "," in head else ("\t" if "\t" in head and ";" not in head else None)
    if ";" in head and "," not in head:
        delimiter = ";"
    tokens = [t.strip() for t in head.split(delimiter)]
    header: list[str] | None = None
    start = first
    if not all(_is_number(t) for t in tokens):
        header = [t.strip("\"' ") for t in tokens]
        start = first + 1
    if delimiter == "\t":
        delimiter = None  # tabs are whitespace; loadtxt's default copes with mixed runs
    body = "\n".join(lines[start:])
    table = loadtxt_lines(
        body,
        name,
        first_line=start + 1,
        n_cols=len(header) if header else None,
        delimiter=delimiter,
    )
    if table.shape[1] < 3:
        raise CloudFormatError(f"{name}: needs at least 3 columns (x y z), found {table.shape[1]}")
    names = header or [f"col{i}" for i in range(table.shape[1])]
    lower = [n.lower() for n in names]
    if header and all(c in lower for c in ("x", "y", "z")):
        xyz_idx = [lower.index(c) for c in ("x", "y", "z")]
    else:
        xyz_idx = [0, 1, 2]
    fields: dict[str, np.ndarray] = {}
    for i, n in enumerate(names):
        if i in xyz_idx:
            continue
        key = n if n and n not in fields else f"col{i}"
        fields[key] = table[:, i].copy()
    return RawCloud(xyz=np.ascontiguousarray(table[:, xyz_idx]), fields=combine_rgb(fields))


_VERTEX = re.compile(r"^v[ \t]+([^\n#]*)", re.MULTILINE)


def read_obj(path: Path, name: str) -> RawCloud:
    """Read ``v x y z [w] [r g b]`` vertex lines of an OBJ file; everything else is ignored."""
    text = _read_text(path, name)
    rows = _VERTEX.findall(text)
    if not rows:
        return RawCloud(xyz=np.zeros((0, 3)))
    try:
        table = np.loadtxt(rows, dtype=np.float64, ndmin=2)
    except ValueError as err:
        raise CloudFormatError(f"{name}: {_bad_obj_line(text)}") from err
    n_cols = table.shape[1]
    if n_cols < 3:
        raise CloudFormatError(f"{name}: {_bad_obj_line(text)}")
    fields: dict[str, np.ndarray] = {}
    if n_cols >= 6:
        # the common "v x y z r g b" extension; colour is 0..1 (MeshLab) or 0..255
        fields["rgb"] = to_uint8_colour(table[:, 3:6])
    return RawCloud(xyz=np.ascontiguousarray(table[:, :3]), fields=fields)


def _bad_obj_line(text: str) -> str:
    expected: int | None = None
    for m in _VERTEX.finditer(text):
        lineno = text.count("\n", 0, m.start()) + 1
        toks = m.group(1).split()
        for t in toks:
            if not _is_number(t):
                return f"line {lineno}: cannot parse {t[:30]!r} as a number"
        if len(toks) < 3:
            return f"line {lineno}: vertex needs x y z, found {len(toks)} values"
        if expected is None:
            expected = len(toks)
        elif len(toks) != expected:
            return f"line {lineno}: expected {expected} values, found {len(toks)}"
    return "unparsable vertex data"
