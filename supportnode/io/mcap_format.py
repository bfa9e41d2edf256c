"""The MCAP layout of supportnode messages: channel encodings, schemas, message packing.

Each MCAP message is one msgpack array ``[header, bin(buffer 0), ..., bin(buffer B-1)]`` whose
first element is the wire header (frame 1) byte for byte, so a recorded message replays as
exactly the frames that were received. The channel's schema (``supportnode/<Type>``, encoding
``jsonschema``) describes that array. Shared by the writer (`supportnode.io.recording`) and the
reader (`supportnode.io.mcap_reader`). See docs/protocol.md section 12.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from typing import Any

import msgpack

from supportnode.errors import SupportNodeError
from supportnode.msgs import SCHEMA_VERSION, Limits

__all__ = [
    "COMPRESSIONS",
    "MESSAGE_ENCODING",
    "SCHEMA_ENCODING",
    "SCHEMA_PREFIX",
    "RecordingError",
    "pack_message",
    "schema_json",
    "unpack_message",
]

#: MCAP channel message encoding of our messages (a well-known MCAP encoding: one msgpack value).
MESSAGE_ENCODING = "msgpack"
#: MCAP schema encoding of our schemas.
SCHEMA_ENCODING = "jsonschema"
#: Schema names are this prefix plus the message type, e.g. ``supportnode/PointCloud``.
SCHEMA_PREFIX = "supportnode/"
COMPRESSIONS = ("zstd", "lz4", "none")

_MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_DATA_END = 0x0F
_COMMON_KEYS = ("type", "version", "stamp", "frame_id", "seq", "buffers")


class RecordingError(SupportNodeError):
    """An MCAP recording cannot be written or read (not MCAP, unreadable, bad message)."""


def _require_mcap() -> None:
    """One clear line instead of a traceback when the mcap package is missing."""
    try:
        import mcap  # noqa: F401
    except ImportError as err:
        raise RecordingError("MCAP recordings need the mcap package: pip install mcap") from err


def schema_json(type_name: str) -> bytes:
    """The JSON Schema stored with a channel of ``type_name`` messages (deterministic bytes).

    JSON Schema cannot say "msgpack bin"; the description says it, and docs/protocol.md is the
    specification of the header and the buffers.
    """
    schema = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": f"{SCHEMA_PREFIX}{type_name}",
        "description": (
            f"supportnode {type_name} message, wire schema version {SCHEMA_VERSION} "
            "(docs/protocol.md), as one msgpack array: the wire header map (frame 1, byte for "
            "byte), then one msgpack bin per buffer frame, in the order of header.buffers"
        ),
        "type": "array",
        "prefixItems": [
            {
                "type": "object",
                "required": list(_COMMON_KEYS),
                "properties": {
                    "type": {"const": type_name},
                    "version": {"const": SCHEMA_VERSION},
                    "stamp": {"type": "number", "description": "seconds"},
                    "frame_id": {"type": "string"},
                    "seq": {"type": "integer", "minimum": 0},
                    "buffers": {
                        "type": "array",
                        "items": {
                            "type": "object",
                            "required": ["name", "dtype", "shape"],
                            "properties": {
                                "name": {"type": "string"},
                                "dtype": {"type": "string"},
                                "shape": {"type": "array", "items": {"type": "integer"}},
                            },
                        },
                    },
                },
            }
        ],
        "items": {"description": "msgpack bin: raw little-endian bytes of one buffer"},
    }
    return json.dumps(schema, sort_keys=True, separators=(",", ":")).encode()


def _array_header(n: int) -> bytes:
    if n < 16:
        return bytes([0x90 | n])
    if n < 1 << 16:
        return b"\xdc" + struct.pack(">H", n)
    return b"\xdd" + struct.pack(">I", n)


def _bin_header(n: int) -> bytes:
    if n < 1 << 8:
        return b"\xc4" + bytes([n])
    if n < 1 << 16:
        return b"\xc5" + struct.pack(">H", n)
    return b"\xc6" + struct.pack(">I", n)


def _bytes_view(frame: Any) -> memoryview:
    mv = memoryview(frame)
    return mv.cast("B") if mv.nbytes and mv.format != "B" else mv


def pack_message(frames: Sequence[Any]) -> bytes:
    """MCAP message data of wire ``frames`` ``[topic, header, *buffers]`` (the topic is the
    channel's): msgpack array ``[header, bin(buffer), ...]``, the header embedded unchanged."""
    if len(frames) < 2:
        raise RecordingError(f"a message needs [topic, header, *buffers], got {len(frames)} frames")
    parts: list[Any] = [_array_header(len(frames) - 1), _bytes_view(frames[1])]
    for buf in frames[2:]:
        mv = _bytes_view(buf)
        parts += [_bin_header(mv.nbytes), mv]
    return b"".join(parts)


def unpack_message(topic: str | bytes, data: bytes | memoryview) -> list[bytes | memoryview]:
    """Wire frames ``[topic, header, *buffers]`` of MCAP message ``data`` (see `pack_message`).

    The header and buffers are zero-copy views of ``data``. Raises RecordingError when ``data``
    is not such an array (the header's contents are checked later, by the message decoder).
    """
    mv = memoryview(data).cast("B") if memoryview(data).format != "B" else memoryview(data)
    topic_b = topic.encode() if isinstance(topic, str) else bytes(topic)
    size = mv.nbytes
    if size < 2:
        raise RecordingError("message data is too short to be a msgpack array")
    lead = mv[0]
    if lead & 0xF0 == 0x90:
        n, pos = lead & 0x0F, 1
    elif lead == 0xDC and size >= 3:
        n, pos = struct.unpack_from(">H", mv, 1)[0], 3
    elif lead == 0xDD and size >= 5:
        n, pos = struct.unpack_from(">I", mv, 1)[0], 5
    else:
        raise RecordingError("message data is not a msgpack array [header, *buffers]")
    if n < 1:
        raise RecordingError("message data is an empty array (no header)")
    # The header's length is that of one msgpack value: let msgpack find its end, feeding a
    # growing prefix so that a small header never costs a copy of the buffers behind it.
    limit = Limits().max_header_bytes
    want = 4096
    while True:
        unpacker = msgpack.Unpacker(max_buffer_size=limit + 16)
        unpacker.feed(mv[pos : pos + want])
        try:
            unpacker.skip()
            break
        except msgpack.OutOfData:
            if pos + want >= size or want > limit:
                raise RecordingError("message header is truncated or too large") from None
            want *= 4
        except Exception as err:  # msgpack's format errors are ValueError subclasses
            raise RecordingError(f"message header is not msgpack ({err})") from None
    end = pos + unpacker.tell()
    frames: list[bytes | memoryview] = [topic_b, mv[pos:end]]
    pos = end
    for i in range(n - 1):
        if pos >= size:
            raise RecordingError(f"message data ends before buffer {i}")
        lead = mv[pos]
        if lead == 0xC4 and pos + 2 <= size:
            length, pos = mv[pos + 1], pos + 2
        elif lead == 0xC5 and pos + 3 <= size:
            length, pos = struct.unpack_from(">H", mv, pos + 1)[0], pos + 3
        elif lead == 0xC6 and pos + 5 <= size:
            length, pos = struct.unpack_from(">I", mv, pos + 1)[0], pos + 5
        else:
            raise RecordingError(f"buffer {i} of the message is not a msgpack bin")
        if pos + length > size:
            raise RecordingError(f"buffer {i} of the message is truncated")
        frames.append(mv[pos : pos + length])
        pos += length
    if pos != size:
        raise RecordingError(f"{size - pos} stray bytes after the message's last buffer")
    return frames


def one_line(err: BaseException) -> str:
    """An exception as one line of at most 120 characters."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= 120 else text[:117] + "..."
