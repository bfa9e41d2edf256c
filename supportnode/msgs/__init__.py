"""The wire protocol: typed messages as ZeroMQ multipart ``[topic, header, *buffers]``.

The header is a msgpack map (type, schema version, stamp, frame_id, seq, buffer layouts and
type-specific keys); arrays travel as raw little-endian buffers, zero-copy on send. Decoding
validates everything and raises exactly one `ProtocolError` (one line naming the topic) on any
problem, never allocating more than the limits allow. Pure: no sockets. See docs/protocol.md.

    frames = PointCloud.from_xyz(points, stamp=t, frame_id="lidar").encode("scan")
    msg = decode_any(frames)            # -> PointCloud
"""

from __future__ import annotations

from typing import Any, TypeAlias

from supportnode.msgs._wire import (
    DTYPES,
    SCHEMA_VERSION,
    BufferSpec,
    Header,
    Limits,
    parse_frames,
)
from supportnode.msgs.diagnostics import LEVELS, Diagnostics, LatencyStats
from supportnode.msgs.pointcloud import PointCloud, Pose
from supportnode.msgs.results import (
    ObstacleCluster,
    ObstacleClusters,
    SupportSurface,
    SupportSurfaces,
)
from supportnode.msgs.sequence import MAX_SEQ_GAP, SeqCounter

__all__ = [
    "DTYPES",
    "LEVELS",
    "MAX_SEQ_GAP",
    "MESSAGE_TYPES",
    "SCHEMA_VERSION",
    "BufferSpec",
    "Diagnostics",
    "Header",
    "LatencyStats",
    "Limits",
    "Message",
    "ObstacleCluster",
    "ObstacleClusters",
    "PointCloud",
    "Pose",
    "SeqCounter",
    "SupportSurface",
    "SupportSurfaces",
    "decode_any",
    "peek_header",
]

Message: TypeAlias = "PointCloud | SupportSurfaces | ObstacleClusters | Diagnostics"

#: Header ``type`` -> message class.
MESSAGE_TYPES: dict[str, Any] = {
    "PointCloud": PointCloud,
    "SupportSurfaces": SupportSurfaces,
    "ObstacleClusters": ObstacleClusters,
    "Diagnostics": Diagnostics,
}


def peek_header(frames: Any, limits: Limits | None = None) -> Header:
    """The validated common header (topic, type, version, stamp, frame_id, seq, buffer layouts,
    each buffer's size checked against its frame) without looking at array contents: cheap
    filtering by type, stamp or size before a full decode. Raises ProtocolError."""
    header, _ = parse_frames(frames, limits or Limits())
    return header


def decode_any(
    frames: Any, limits: Limits | None = None, *, drop_nonfinite: bool = True
) -> Message:
    """Decode and validate a message of any type (dispatch on the header's ``type``).

    drop_nonfinite: for PointCloud, see `PointCloud.decode`. Raises ProtocolError.
    """
    limits = limits or Limits()
    header, buffers = parse_frames(frames, limits)
    if header.type == "PointCloud":
        return PointCloud._from_parsed(header, buffers, limits, drop_nonfinite)
    cls = MESSAGE_TYPES[header.type]  # parse_frames accepted only known types
    msg: Message = cls._from_parsed(header, buffers, limits)
    return msg
