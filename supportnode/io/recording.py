"""MCAP recordings of supportnode messages: write them, read them back (also damaged files).

One MCAP channel per (topic, message type), message encoding ``msgpack``: each MCAP message is
one msgpack array ``[header, bin(buffer 0), ..., bin(buffer B-1)]`` whose first element is the
wire header (frame 1) byte for byte, so a recorded message replays as exactly the frames that
were received. The channel's schema (``supportnode/<Type>``, encoding ``jsonschema``) describes
that array; ``log_time`` is the receive time, ``publish_time`` the message stamp (ns), both ns
since the Unix epoch. Chunks are zstd (default) or lz4 compressed and indexed. See
docs/protocol.md section 12.

    with RecordingWriter("run.mcap") as rec:
        rec.write(frames, receive_time=time.time())
    with McapFile("run.mcap") as f:
        for m in f.messages():            # RawMessage: channel, log_time, data, ...
            frames = m.frames()           # [topic, header, *buffers] of our messages

Reading never trusts the file: a missing footer (recorder killed), a truncated or corrupt chunk
gives one warning line in ``McapFile.warnings`` and everything readable is still returned.
"""

from __future__ import annotations

import heapq
import io
import json
import os
import struct
import time
from collections.abc import Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import msgpack

from supportnode import __version__
from supportnode._closing import Closing
from supportnode.errors import SupportNodeError
from supportnode.msgs import SCHEMA_VERSION, Header, Limits, peek_header

__all__ = [
    "MESSAGE_ENCODING",
    "SCHEMA_ENCODING",
    "SCHEMA_PREFIX",
    "ChannelInfo",
    "McapFile",
    "RawMessage",
    "RecordingError",
    "RecordingWriter",
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


# ------------------------------------------------------------------------------ message packing


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


# ------------------------------------------------------------------------------------- writing


def _ns(seconds: float) -> int:
    """Seconds -> MCAP nanoseconds (uint64; negative times clamp to 0)."""
    return max(0, min(round(seconds * 1e9), (1 << 64) - 1))


@dataclass
class TopicCount:
    """What a writer wrote on one topic."""

    type: str
    messages: int = 0
    bytes: int = 0


class RecordingWriter(Closing):
    """Writes supportnode messages to an MCAP file.

    compression: "zstd" (default: about 2x smaller than lz4 on scans, ~0.3 GB/s per core), "lz4"
    (faster) or "none". chunk_size: uncompressed bytes per chunk. flush_interval: seconds after
    which a chunk is closed and flushed to the OS even if not full, so that a killed recorder
    loses at most that much (a file read back without its footer stops at the last complete
    chunk). metadata: extra key-value strings stored in the file's "supportnode" metadata.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        compression: str = "zstd",
        chunk_size: int = 4 << 20,
        flush_interval: float = 1.0,
        metadata: Mapping[str, str] | None = None,
        limits: Limits | None = None,
    ) -> None:
        _require_mcap()
        from mcap.writer import CompressionType, Writer

        if compression not in COMPRESSIONS:
            raise RecordingError(f"compression must be one of {', '.join(COMPRESSIONS)}")
        self.path = os.fspath(path)
        self.limits = limits or Limits()
        self.flush_interval = flush_interval
        self.topics: dict[str, TopicCount] = {}
        self.messages = 0
        try:
            self._file: BinaryIO = open(self.path, "wb")  # closed by close()
        except OSError as err:
            raise RecordingError(f"{self.path}: cannot write ({err.strerror or err})") from err
        kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}
        self._writer = Writer(
            self._file,
            chunk_size=chunk_size,
            compression=kind.get(compression, CompressionType.NONE),
        )
        self._writer.start(profile="", library=f"supportnode {__version__}")
        meta = {"protocol_version": str(SCHEMA_VERSION), "writer": f"supportnode {__version__}"}
        meta.update(metadata or {})
        self._writer.add_metadata("supportnode", meta)
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._unflushed_since: float | None = None
        self._closed = False

    def _channel(self, topic: str, type_name: str) -> int:
        key = (topic, type_name)
        if key not in self._channels:
            if type_name not in self._schemas:
                self._schemas[type_name] = self._writer.register_schema(
                    f"{SCHEMA_PREFIX}{type_name}", SCHEMA_ENCODING, schema_json(type_name)
                )
            self._channels[key] = self._writer.register_channel(
                topic, MESSAGE_ENCODING, self._schemas[type_name]
            )
        return self._channels[key]

    def write(
        self, frames: Sequence[Any], receive_time: float | None = None, header: Header | None = None
    ) -> Header:
        """Record wire ``frames`` ``[topic, header, *buffers]`` received at ``receive_time``
        (seconds since the epoch; default now). The header is validated (`peek_header`, raises
        ProtocolError) unless the caller passes the one it already has. Returns the header."""
        if self._closed:
            raise RecordingError(f"{self.path}: recording is closed")
        if header is None:
            header = peek_header(frames, self.limits)
        data = pack_message(frames)
        channel = self._channel(header.topic, header.type)
        self._writer.add_message(
            channel_id=channel,
            log_time=_ns(time.time() if receive_time is None else receive_time),
            data=data,
            publish_time=_ns(header.stamp),
            sequence=header.seq & 0xFFFFFFFF,  # MCAP's sequence is uint32; the header has all
        )
        stats = self.topics.setdefault(header.topic, TopicCount(header.type))
        stats.messages += 1
        stats.bytes += len(data)
        self.messages += 1
        if self._unflushed_since is None:
            self._unflushed_since = time.monotonic()
        self.tick()
        return header

    def tick(self) -> None:
        """Flush if the open chunk is older than ``flush_interval``; call it also when idle, so
        that the last messages before a quiet spell reach the disk."""
        since = self._unflushed_since
        if since is not None and time.monotonic() - since >= self.flush_interval:
            self.flush()

    def flush(self) -> None:
        """Close the open chunk and hand everything to the OS (survives the process dying)."""
        self._writer.flush()
        self._file.flush()
        self._unflushed_since = None

    def close(self) -> None:
        """Write the summary (indexes, statistics) and footer, and close the file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()


# ------------------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class ChannelInfo:
    """One MCAP channel with its schema (empty strings when it has none)."""

    id: int
    topic: str
    message_encoding: str
    schema_name: str = ""
    schema_encoding: str = ""
    schema_data: bytes = field(default=b"", repr=False)

    @property
    def is_supportnode(self) -> bool:
        """A channel of our own messages."""
        return self.message_encoding == MESSAGE_ENCODING and self.schema_name.startswith(
            SCHEMA_PREFIX
        )

    @property
    def type(self) -> str:
        """Message type: ours without the prefix, else the schema name (e.g. a ROS type)."""
        if self.is_supportnode:
            return self.schema_name[len(SCHEMA_PREFIX) :]
        return self.schema_name or "?"


@dataclass
class RawMessage:
    """One MCAP message: times in ns since the epoch (log = received, publish = stamped)."""

    channel: ChannelInfo
    log_time: int
    publish_time: int
    sequence: int
    data: bytes

    def frames(self) -> list[bytes | memoryview]:
        """Wire frames of one of our messages (RecordingError if it is not ours or damaged)."""
        if not self.channel.is_supportnode:
            raise RecordingError(
                f"topic {self.channel.topic!r}: {self.channel.message_encoding} message of "
                f"type {self.channel.type} is not a supportnode message"
            )
        return unpack_message(self.channel.topic, self.data)


@dataclass
class McapStats:
    """What the summary section says (None fields: the file has no summary)."""

    message_count: int | None = None
    start_time: int | None = None  # ns
    end_time: int | None = None  # ns
    channel_counts: dict[int, int] = field(default_factory=dict)
    chunk_count: int = 0
    compression: set[str] = field(default_factory=set)
    compressed_bytes: int = 0
    uncompressed_bytes: int = 0


class McapFile(Closing):
    """An MCAP file opened for reading: channels, summary, messages in log-time order.

    Indexed files are read chunk by chunk through the chunk index (``messages(start=...)``
    seeks); a file without a usable summary (a killed recorder's) is read linearly up to its
    last complete record. Damage never raises from `messages`: it ends or skips what is
    unreadable and appends one line to ``warnings``. Opening a file that is not MCAP raises
    RecordingError.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        _require_mcap()
        self.path = os.fspath(path)
        self.warnings: list[str] = []
        self.channels: dict[int, ChannelInfo] = {}
        self.stats = McapStats()
        self.metadata: dict[str, dict[str, str]] = {}
        p = Path(self.path)
        if not p.exists():
            raise RecordingError(f"{self.path}: no such file")
        if p.is_dir():
            raise RecordingError(f"{self.path}: is a directory, not an MCAP file")
        try:
            self._file: BinaryIO = open(self.path, "rb")  # closed by close()
        except OSError as err:
            raise RecordingError(f"{self.path}: cannot read ({err.strerror or err})") from err
        self.size = p.stat().st_size
        if self._file.read(8) != _MAGIC:
            self._file.close()
            raise RecordingError(f"{self.path}: not an MCAP file (bad magic bytes)")
        self._schemas: dict[int, Any] = {}
        self._chunk_indexes: list[Any] | None = None
        self._linear_scanned = False
        self._unfinalised = False
        self._read_summary()

    # -- summary
    def _read_summary(self) -> None:
        """Use the footer's summary when the file is complete; else note why it is not."""
        from mcap.exceptions import McapError
        from mcap.reader import SeekingReader

        self._file.seek(-8, io.SEEK_END)
        if self.size < 16 or self._file.read(8) != _MAGIC:
            # Said once, with what was read, when the linear read ends (see _linear).
            self._unfinalised = True
            return
        try:
            self._file.seek(0)
            summary = SeekingReader(self._file).get_summary()
        except (McapError, ValueError, struct.error, OSError, KeyError) as err:
            self.warnings.append(
                f"{self.path}: summary unreadable ({_one_line(err)}): reading linearly"
            )
            return
        if summary is None:
            return
        for sid, s in summary.schemas.items():
            self._schemas[sid] = s
        for _cid, c in summary.channels.items():
            self._add_channel(c)
        if summary.statistics is not None:
            st = summary.statistics
            self.stats.message_count = st.message_count
            self.stats.channel_counts = dict(st.channel_message_counts)
            if st.message_count:
                self.stats.start_time, self.stats.end_time = (
                    st.message_start_time,
                    st.message_end_time,
                )
        self.stats.chunk_count = len(summary.chunk_indexes)
        for ci in summary.chunk_indexes:
            self.stats.compression.add(ci.compression or "none")
            self.stats.compressed_bytes += ci.compressed_size
            self.stats.uncompressed_bytes += ci.uncompressed_size
        # The index is only useful when every chunk's messages can be found through it.
        if summary.chunk_indexes and summary.channels:
            self._chunk_indexes = sorted(
                summary.chunk_indexes, key=lambda c: (c.message_start_time, c.chunk_start_offset)
            )
        self.metadata = self._read_metadata(summary)

    def _read_metadata(self, summary: Any) -> dict[str, dict[str, str]]:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Metadata

        out: dict[str, dict[str, str]] = {}
        for mi in summary.metadata_indexes:
            try:
                self._file.seek(mi.offset + 9)
                rec = Metadata.read(ReadDataStream(self._file))
                out[rec.name] = dict(rec.metadata)
            except Exception:  # metadata is informational: never fail a read for it
                continue
        return out

    def _add_channel(self, c: Any) -> None:
        s = self._schemas.get(c.schema_id)
        self.channels[c.id] = ChannelInfo(
            id=c.id,
            topic=c.topic,
            message_encoding=c.message_encoding,
            schema_name=s.name if s is not None else "",
            schema_encoding=s.encoding if s is not None else "",
            schema_data=bytes(s.data) if s is not None else b"",
        )

    @property
    def indexed(self) -> bool:
        """Whether the file has a chunk index (complete file; `messages` can seek)."""
        return self._chunk_indexes is not None

    def scan_channels(self) -> dict[int, ChannelInfo]:
        """All channels; an unindexed file is read through once to find them."""
        if not self.indexed and not self._linear_scanned:
            for _ in self.messages():
                pass
        return self.channels

    # -- messages
    def messages(
        self,
        topics: Collection[str] | None = None,
        start: int | None = None,
        end: int | None = None,
    ) -> Iterator[RawMessage]:
        """Messages with ``start <= log_time < end`` (ns; None: unbounded) on ``topics``
        (None: all), in log-time order for indexed files, file order otherwise."""
        if self._chunk_indexes is not None:
            yield from self._indexed(topics, start, end)
        else:
            yield from self._linear(topics, start, end)

    def _keep(
        self, m: Any, topics: Collection[str] | None, start: int | None, end: int | None
    ) -> bool:
        ch = self.channels.get(m.channel_id)
        if ch is None:
            return False
        if topics is not None and ch.topic not in topics:
            return False
        if start is not None and m.log_time < start:
            return False
        return not (end is not None and m.log_time >= end)

    def _records_of_chunk(self, body: bytes, offset: int) -> list[Any] | None:
        """Records in a chunk record's body, or None (and a warning) when it is damaged."""
        from mcap.data_stream import ReadDataStream
        from mcap.records import Chunk
        from mcap.stream_reader import breakup_chunk

        try:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
            if len(chunk.data) == 0 and chunk.uncompressed_size:
                raise ValueError("empty chunk data")
            return breakup_chunk(chunk, validate_crc=True)
        except Exception as err:  # zstd/lz4 errors, CRC mismatch, struct errors, EndOfFile
            self._warn(
                f"{self.path}: chunk at byte {offset} is corrupt ({_one_line(err)}): skipped"
            )
            return None

    def _register(self, rec: Any) -> None:
        from mcap.records import Channel, Schema

        if isinstance(rec, Schema):
            self._schemas[rec.id] = rec
        elif isinstance(rec, Channel) and rec.id not in self.channels:
            self._add_channel(rec)

    def _indexed(
        self, topics: Collection[str] | None, start: int | None, end: int | None
    ) -> Iterator[RawMessage]:
        from mcap.records import Message

        assert self._chunk_indexes is not None
        wanted = None
        if topics is not None:
            wanted = {cid for cid, ch in self.channels.items() if ch.topic in topics}
        heap: list[tuple[int, int, int, Any]] = []
        for order, ci in enumerate(self._chunk_indexes):
            if end is not None and ci.message_start_time >= end:
                break  # sorted by start time: no later chunk has anything before `end`
            if start is not None and ci.message_end_time < start:
                continue
            if (
                wanted is not None
                and ci.message_index_offsets
                and not (wanted & set(ci.message_index_offsets))
            ):
                continue
            # Merge: every message not yet loaded is at or after this chunk's start.
            while heap and heap[0][0] < ci.message_start_time:
                yield self._raw(heapq.heappop(heap)[3])
            body = self._read_record_at(ci.chunk_start_offset)
            if body is None:
                continue
            records = self._records_of_chunk(body, ci.chunk_start_offset)
            for i, rec in enumerate(records or ()):
                if isinstance(rec, Message):
                    if self._keep(rec, topics, start, end):
                        heapq.heappush(heap, (rec.log_time, order, i, rec))
                else:
                    self._register(rec)
        while heap:
            yield self._raw(heapq.heappop(heap)[3])

    def _read_record_at(self, offset: int) -> bytes | None:
        try:
            self._file.seek(offset)
            head = self._file.read(9)
            if len(head) == 9:
                _, length = struct.unpack("<BQ", head)
                if offset + 9 + length <= self.size:
                    return self._file.read(length)
        except OSError:
            pass
        self._warn(f"{self.path}: chunk at byte {offset} lies past the end of the file: skipped")
        return None

    def _linear(
        self, topics: Collection[str] | None, start: int | None, end: int | None
    ) -> Iterator[RawMessage]:
        """Records in file order up to the footer, the data section's end or the damage."""
        from mcap.data_stream import ReadDataStream
        from mcap.records import Message

        f = self._file
        pos, count = 8, 0  # count: messages in the file so far, whatever the filters
        ended = False  # reached the end of the data section
        while True:
            f.seek(pos)
            head = f.read(9)
            if len(head) < 9:
                self._warn(f"{self.path}: {self._cut(pos)}: {count} messages read")
                break
            opcode, length = struct.unpack("<BQ", head)
            if pos + 9 + length > self.size:
                self._warn(
                    f"{self.path}: {self._cut(pos)}: {count} messages read from complete chunks"
                )
                break
            body = f.read(length)
            stream = ReadDataStream(io.BytesIO(body))
            try:
                if opcode == _OP_CHUNK:
                    records = self._records_of_chunk(body, pos) or []
                elif opcode == _OP_MESSAGE:
                    records = [Message.read(stream, length)]
                elif opcode in (_OP_SCHEMA, _OP_CHANNEL):
                    from mcap.records import Channel, Schema

                    records = [(Schema if opcode == _OP_SCHEMA else Channel).read(stream)]
                else:
                    records = []
            except Exception as err:
                self._warn(f"{self.path}: record at byte {pos} is corrupt ({_one_line(err)})")
                break
            for rec in records:
                if isinstance(rec, Message):
                    count += 1
                    if self._keep(rec, topics, start, end):
                        yield self._raw(rec)
                else:
                    self._register(rec)
            pos += 9 + length
            if opcode in (_OP_FOOTER, _OP_DATA_END):
                ended = True
                break
            if opcode == 0 or opcode > 0x7F:  # not an MCAP record: the rest is garbage
                self._warn(f"{self.path}: unknown record 0x{opcode:02x} at byte {pos}")
                break
        if ended and self._unfinalised:
            self._warn(f"{self.path}: not finalised (no footer): all {count} messages read")
        self._linear_scanned = True

    def _warn(self, text: str) -> None:
        """Each problem once, however often the file is read."""
        if text not in self.warnings:
            self.warnings.append(text)

    def _cut(self, pos: int) -> str:
        """Why a linear read stops at byte ``pos`` before the footer."""
        why = "not finalised (recorder killed?)" if self._unfinalised else "truncated"
        if pos >= self.size:
            return f"{why}, ends after its last complete chunk at byte {self.size}"
        return f"{why}, ends at byte {self.size} inside the record at byte {pos}"

    def _raw(self, rec: Any) -> RawMessage:
        return RawMessage(
            self.channels[rec.channel_id], rec.log_time, rec.publish_time, rec.sequence, rec.data
        )

    def close(self) -> None:
        """Close the file (idempotent)."""
        self._file.close()


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= 120 else text[:117] + "..."
