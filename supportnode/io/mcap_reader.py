"""Reading MCAP recordings of supportnode messages, also damaged ones.

    with McapFile("run.mcap") as f:
        for m in f.messages():            # RawMessage: channel, log_time, data, ...
            frames = m.frames()           # [topic, header, *buffers] of our messages

Reading never trusts the file: a missing footer (recorder killed), a truncated or corrupt chunk
gives one warning line in ``McapFile.warnings`` and everything readable is still returned.
"""

from __future__ import annotations

import heapq
import io
import os
import struct
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from supportnode._closing import Closing
from supportnode.io.mcap_format import (
    _MAGIC,
    _OP_CHANNEL,
    _OP_CHUNK,
    _OP_DATA_END,
    _OP_FOOTER,
    _OP_MESSAGE,
    _OP_SCHEMA,
    MESSAGE_ENCODING,
    SCHEMA_PREFIX,
    RecordingError,
    _require_mcap,
    one_line,
    unpack_message,
)

__all__ = ["ChannelInfo", "McapFile", "McapStats", "RawMessage"]


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
                f"{self.path}: summary unreadable ({one_line(err)}): reading linearly"
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
            self._warn(f"{self.path}: chunk at byte {offset} is corrupt ({one_line(err)}): skipped")
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
                self._warn(f"{self.path}: record at byte {pos} is corrupt ({one_line(err)})")
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
