"""Framing shared by every message: ``[topic, header, *buffers]``, and the checks behind decoding.

The header is a msgpack map; each buffer is the raw little-endian bytes of one array whose name,
dtype string and shape the header's ``buffers`` list gives, in frame order. Everything here is
pure (no sockets): frames in, validated header and zero-copy array views out, or one
`ProtocolError` naming the topic and the problem. See docs/protocol.md for the specification.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, TypeVar

import msgpack
import numpy as np

from supportnode.errors import ConfigError, ProtocolError
from supportnode.msgs._check import Check, dtype_choices, kind_of, short

__all__ = [
    "DTYPES",
    "FLOAT_DTYPES",
    "MESSAGE_TYPE_NAMES",
    "SCHEMA_VERSION",
    "BufferSpec",
    "Check",
    "Header",
    "Limits",
    "encode_frames",
    "parse_frames",
    "short",
]

#: Schema version this node reads and writes (the header's ``version``).
SCHEMA_VERSION = 1
#: Names of the message types (the header's ``type``).
MESSAGE_TYPE_NAMES = ("PointCloud", "SupportSurfaces", "ObstacleClusters", "Diagnostics")
#: Accepted dtype strings: numpy's own spelling of little-endian numbers. Object, structured,
#: bool, complex, half, datetime and big-endian dtypes are rejected; matching whole strings
#: (never calling ``np.dtype`` on a received string) keeps hostile dtype specs out of numpy.
DTYPES = frozenset({"<f4", "<f8", "|u1", "|i1", "<u2", "<i2", "<u4", "<i4", "<u8", "<i8"})
FLOAT_DTYPES = frozenset({"<f4", "<f8"})
#: Longest topic, bytes (ZeroMQ allows more; nothing sane needs it).
MAX_TOPIC_BYTES = 255
#: Most dimensions of one buffer.
MAX_NDIM = 4
# Buffer and field names: C identifiers, so a C++ or ROS bridge can use them as member names.
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}\Z")
# seq is a uint64 on the wire.
_UINT64_MAX = (1 << 64) - 1


@dataclass(frozen=True)
class Limits:
    """Size limits of decoded messages; anything larger is rejected before arrays are made.

    Defaults fit 131,072-point lidar scans (and 30 of them merged) comfortably.
    """

    max_points: int = 4_000_000  # points of a PointCloud, or subsampled points of all clusters
    max_header_bytes: int = 1 << 20  # msgpack header frame, bytes
    max_buffers: int = 64  # buffer frames after the header
    max_surfaces: int = 10_000  # surfaces in one SupportSurfaces
    max_clusters: int = 100_000  # clusters in one ObstacleClusters
    max_polygon_vertices: int = 1_000_000  # outline vertices (and rings) of one SupportSurfaces
    max_message_bytes: int = 256 << 20  # all frames together, bytes

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"Limits.{f.name} must be a positive integer, got {value!r}")


@dataclass(frozen=True)
class BufferSpec:
    """Layout of one buffer frame: name, dtype string (e.g. '<f4') and shape."""

    name: str
    dtype: str
    shape: tuple[int, ...]


@dataclass(frozen=True)
class Header:
    """The validated common part of a message header (what `peek_header` returns).

    ``raw`` is the whole decoded msgpack map, type-specific keys included (not yet validated).
    """

    topic: str
    type: str
    version: int
    stamp: float  # seconds
    frame_id: str
    seq: int
    buffers: tuple[BufferSpec, ...]
    raw: dict[str, Any]


def _topic_name(raw: bytes) -> str:
    # Undecodable topics are still named, readably, in the error.
    return raw[:64].decode("utf-8", "replace")


def _views(frames: Any) -> list[memoryview]:
    if isinstance(frames, (bytes, bytearray, memoryview, str)) or not isinstance(frames, Sequence):
        raise ProtocolError(f"topic ?: message must be a list of frames, got {kind_of(frames)}")
    if len(frames) < 2:
        name = "?"
        if frames:
            try:
                name = _topic_name(bytes(memoryview(frames[0])))
            except TypeError:
                pass
        raise ProtocolError(
            f"topic {name!r}: message has {len(frames)} frame(s), expected [topic, header, *buffers]"
        )
    views = []
    for i, f in enumerate(frames):
        try:
            mv = memoryview(f)
        except TypeError:
            raise ProtocolError(f"topic ?: frame {i} is a {kind_of(f)}, not bytes") from None
        if not mv.c_contiguous:
            raise ProtocolError(f"topic ?: frame {i} is not contiguous memory")
        # Byte view of any buffer format; a zero-size view cannot be cast, and needs no cast.
        views.append(mv.cast("B") if mv.nbytes else memoryview(b""))
    return views


def parse_frames(frames: Any, limits: Limits) -> tuple[Header, dict[str, np.ndarray]]:
    """Validate the framing, the common header keys and every buffer's size against the header.

    Returns the header and the buffers as read-only zero-copy arrays (dtype and shape from the
    header), by name. Type-specific keys and buffer contents are the message classes' job.
    """
    views = _views(frames)
    topic = _topic(bytes(views[0]))
    chk = Check(topic)
    total = sum(v.nbytes for v in views)
    if total > limits.max_message_bytes:
        chk.fail(
            f"message has {total} bytes, exceeds max_message_bytes {limits.max_message_bytes}",
            "oversized",
        )
    if len(views) - 2 > limits.max_buffers:
        chk.fail(f"{len(views) - 2} buffer frames exceed max_buffers {limits.max_buffers}")
    header = chk.as_map(_unpack_header(chk, views[1], limits), "header")
    type_name = chk.as_str(chk.key(header, "type"), "header key 'type'")
    version = chk.as_int(chk.key(header, "version"), "header key 'version'")
    if version != SCHEMA_VERSION:
        chk.fail(
            f"unsupported schema version {version} (this node speaks {SCHEMA_VERSION})", "version"
        )
    if type_name not in MESSAGE_TYPE_NAMES:
        chk.fail(f"unknown message type {short(type_name)}")
    stamp = chk.as_float(chk.key(header, "stamp"), "header key 'stamp'")
    frame_id = chk.as_str(chk.key(header, "frame_id"), "header key 'frame_id'")
    seq = chk.as_int(chk.key(header, "seq"), "header key 'seq'", 0, _UINT64_MAX)
    specs = _buffer_specs(chk, chk.key(header, "buffers"), len(views) - 2)
    arrays: dict[str, np.ndarray] = {}
    for spec, view in zip(specs, views[2:], strict=True):
        itemsize = int(spec.dtype[2:])
        want = math.prod(spec.shape) * itemsize  # Python ints: no overflow on hostile shapes
        if view.nbytes != want:
            chk.fail(
                f"buffer '{spec.name}' has {view.nbytes} bytes, header says "
                f"{spec.shape} '{spec.dtype}' = {want}"
            )
        # Zero-copy: the array views the received frame (read-only when the frame is bytes).
        arrays[spec.name] = np.frombuffer(view, dtype=np.dtype(spec.dtype)).reshape(spec.shape)
    hdr = Header(topic, type_name, version, stamp, frame_id, seq, tuple(specs), header)
    return hdr, arrays


def _topic(raw_topic: bytes) -> str:
    """The topic frame as text: at most MAX_TOPIC_BYTES of UTF-8."""
    if len(raw_topic) > MAX_TOPIC_BYTES:
        raise ProtocolError(
            f"topic {_topic_name(raw_topic)!r}: topic has {len(raw_topic)} bytes "
            f"(at most {MAX_TOPIC_BYTES})"
        )
    try:
        return raw_topic.decode("utf-8")
    except UnicodeDecodeError:
        raise ProtocolError(f"topic {_topic_name(raw_topic)!r}: topic is not UTF-8") from None


def _unpack_header(chk: Check, hb: memoryview, limits: Limits) -> dict[str, Any]:
    """The header frame unpacked: a msgpack map within max_header_bytes."""
    if hb.nbytes > limits.max_header_bytes:
        chk.fail(
            f"header has {hb.nbytes} bytes, exceeds max_header_bytes {limits.max_header_bytes}"
        )
    n = max(hb.nbytes, 1)
    try:
        # Every container and string is bounded by the header's own size, extension types
        # (timestamps, custom) are refused; the C unpacker bounds nesting depth itself.
        header = msgpack.unpackb(
            hb,
            raw=False,
            strict_map_key=True,
            use_list=True,
            max_str_len=n,
            max_bin_len=n,
            max_array_len=n,
            max_map_len=n,
            max_ext_len=0,
        )
    except Exception as err:  # msgpack raises ValueError subclasses, UnicodeDecodeError, ...
        chk.fail(f"header is not valid msgpack ({type(err).__name__}: {short(str(err))})")
    if not isinstance(header, dict):
        chk.fail(f"header must be a msgpack map, got {kind_of(header)}")
    return header


def _buffer_specs(chk: Check, value: Any, frames: int) -> list[BufferSpec]:
    if not isinstance(value, list):
        chk.fail(f"header key 'buffers' must be a list, got {kind_of(value)}")
    if len(value) != frames:
        chk.fail(f"header lists {len(value)} buffers, message has {frames} buffer frames")
    specs: list[BufferSpec] = []
    seen: set[str] = set()
    for i, item in enumerate(value):
        what = f"buffers[{i}]"
        m = chk.as_map(item, what)
        name = chk.as_str(chk.key(m, "name", what), f"{what}.name")
        if not _NAME.match(name):
            chk.fail(f"{what}.name {short(name)} is not an identifier of at most 64 characters")
        if name in seen:
            chk.fail(f"buffer '{name}' appears twice")
        seen.add(name)
        dtype = chk.as_str(chk.key(m, "dtype", what), f"buffer '{name}' dtype")
        if dtype not in DTYPES:
            chk.fail(
                f"buffer '{name}' has unsupported dtype {short(dtype)} (allowed: {dtype_choices(DTYPES)})"
            )
        shape = chk.key(m, "shape", what)
        if not isinstance(shape, list) or not 1 <= len(shape) <= MAX_NDIM:
            chk.fail(f"buffer '{name}' shape must be a list of 1 to {MAX_NDIM} integers")
        dims = tuple(chk.as_int(d, f"buffer '{name}' shape[{j}]", 0) for j, d in enumerate(shape))
        specs.append(BufferSpec(name, dtype, dims))
    return specs


def little_endian(a: np.ndarray) -> np.ndarray:
    """C-contiguous little-endian ``a``, a copy only when it is not already that."""
    a = np.ascontiguousarray(a)
    order = a.dtype.byteorder
    if order == ">" or (order == "=" and sys.byteorder == "big"):
        a = a.astype(a.dtype.newbyteorder("<"))
    return a


def encode_frames(
    topic: str | bytes,
    type_name: str,
    stamp: float,
    frame_id: str,
    seq: int,
    arrays: Sequence[tuple[str, np.ndarray]],
    extra: Mapping[str, Any] | None = None,
) -> list[bytes | memoryview]:
    """``[topic, header, *buffers]`` with the arrays as zero-copy memoryviews where possible.

    ``extra``: type-specific header keys (plain msgpack-able Python values).
    """
    topic_b = topic.encode("utf-8") if isinstance(topic, str) else bytes(topic)
    chk = Check(_topic_name(topic_b))
    if not math.isfinite(stamp):
        chk.fail(f"cannot encode: stamp is {stamp} (must be finite)")
    if isinstance(seq, bool) or not 0 <= int(seq) <= _UINT64_MAX:
        chk.fail(f"cannot encode: seq {seq!r} is not a uint64")
    if not isinstance(frame_id, str):
        chk.fail(f"cannot encode: frame_id must be a string, got {kind_of(frame_id)}")
    specs, bufs = [], []
    for name, a in arrays:
        if not isinstance(name, str) or not _NAME.match(name):
            chk.fail(
                f"cannot encode buffer {short(name)}: not an identifier of at most 64 characters"
            )
        a = little_endian(np.asarray(a))
        if a.dtype.str not in DTYPES:
            chk.fail(
                f"cannot encode buffer '{name}' of dtype {a.dtype.str!r} (allowed: {dtype_choices(DTYPES)})"
            )
        specs.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape)})
        bufs.append(memoryview(a))  # type: ignore[arg-type]  # numpy stubs lack Buffer
    header: dict[str, Any] = {
        "type": type_name,
        "version": SCHEMA_VERSION,
        "stamp": float(stamp),
        "frame_id": frame_id,
        "seq": int(seq),
        "buffers": specs,
    }
    header.update(extra or {})
    return [topic_b, msgpack.packb(header, use_bin_type=True), *bufs]


def expect_type(chk: Check, header: Header, type_name: str) -> None:
    if header.type != type_name:
        chk.fail(f"expected a {type_name} message, got {header.type}")


M = TypeVar("M", bound="Decodable")


class Decodable:
    """``decode(frames)`` for message types that define ``_from_parsed(header, buffers, limits)``."""

    @classmethod
    def decode(cls: type[M], frames: Any, limits: Limits | None = None) -> M:
        """Validated message from ``[topic, header, *buffers]``; any problem is a ProtocolError."""
        limits = limits or Limits()
        header, buffers = parse_frames(frames, limits)
        msg: M = cls._from_parsed(header, buffers, limits)  # type: ignore[attr-defined]
        return msg
