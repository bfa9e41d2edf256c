"""Helpers shared by the cloud readers: the raw result type, ASCII tables, colour packing."""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass, field

import numpy as np

from supportnode.errors import CloudFormatError

# (red, green, blue) property names recognised as colour, in order of preference
RGB_NAMES = (
    ("red", "green", "blue"),
    ("r", "g", "b"),
    ("diffuse_red", "diffuse_green", "diffuse_blue"),
)


@dataclass
class RawCloud:
    """A file's rows before NaN filtering: xyz (M, 3) float64 and fields with M rows."""

    xyz: np.ndarray
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    width: int | None = None
    height: int | None = None
    viewpoint: np.ndarray | None = None
    origin: np.ndarray | None = None  # (3,) metres subtracted from the file's coordinates


def loadtxt_lines(
    text: str,
    name: str,
    first_line: int = 1,
    n_cols: int | None = None,
    delimiter: str | None = None,
) -> np.ndarray:
    """Parse a numeric table (``#`` comments, blank lines skipped) into (M, C) float64.

    ``first_line`` is the file line number of ``text``'s first line, for error messages.
    """
    try:
        with warnings.catch_warnings():
            # an empty table is reported by the caller as "no points", not as a warning
            warnings.simplefilter("ignore", UserWarning)
            table = np.loadtxt(
                io.StringIO(text), dtype=np.float64, comments="#", delimiter=delimiter, ndmin=2
            )
    except ValueError as err:
        # slow path, only on failure: find the offending line to name it
        raise CloudFormatError(
            f"{name}: {_find_bad_line(text, first_line, n_cols, delimiter)}"
        ) from err
    if table.size == 0:
        return np.zeros((0, n_cols or 3), dtype=np.float64)
    if n_cols is not None and table.shape[1] != n_cols:
        raise CloudFormatError(
            f"{name}: line {first_line + _first_data_line(text)}: expected {n_cols} values, "
            f"found {table.shape[1]}"
        )
    return table


def _first_data_line(text: str) -> int:
    for i, line in enumerate(text.splitlines()):
        if line.split("#", 1)[0].strip():
            return i
    return 0


def _find_bad_line(text: str, first_line: int, n_cols: int | None, delimiter: str | None) -> str:
    expected = n_cols
    for i, line in enumerate(text.splitlines()):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        tokens = [t.strip() for t in body.split(delimiter)]
        lineno = first_line + i
        for tok in tokens:
            try:
                float(tok)
            except ValueError:
                return f"line {lineno}: cannot parse {tok[:30]!r} as a number"
        if expected is None:
            expected = len(tokens)
        elif len(tokens) != expected:
            return f"line {lineno}: expected {expected} values, found {len(tokens)}"
    return "unparsable numeric data"


def split_rgb_packed(col: np.ndarray) -> np.ndarray:
    """Unpack 0x(AA)RRGGBB colours stored in a 4-byte float or int column into (N, 3) uint8."""
    u = np.ascontiguousarray(col, dtype=col.dtype.newbyteorder("=")).view(np.uint32)
    return np.column_stack(((u >> 16) & 0xFF, (u >> 8) & 0xFF, u & 0xFF)).astype(np.uint8)


def to_uint8_colour(arr: np.ndarray) -> np.ndarray:
    """Colour channels to uint8: floats in [0, 1] are scaled by 255, others clipped to 0..255."""
    if arr.dtype == np.uint8:
        return arr
    if arr.dtype.kind == "f":
        finite = arr[np.isfinite(arr)]
        if finite.size and finite.max() <= 1.0:
            arr = arr * 255.0
        arr = np.nan_to_num(np.round(arr))
    out: np.ndarray = np.clip(arr, 0, 255).astype(np.uint8)
    return out


def combine_rgb(fields: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Merge separate red/green/blue (or r/g/b) (N,) fields into one "rgb" (N, 3) uint8 field."""
    if "rgb" in fields:
        return fields
    for names in RGB_NAMES:
        if all(n in fields and fields[n].ndim == 1 for n in names):
            rgb = np.column_stack([to_uint8_colour(fields[n]) for n in names])
            out = {k: v for k, v in fields.items() if k not in names}
            out["rgb"] = rgb
            return out
    return fields
