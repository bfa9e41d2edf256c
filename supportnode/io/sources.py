"""Every offline source of scans behind one iterator: `open_source(path).messages()`.

Picked by extension or folder contents, never by probing:

- ``*.mcap``: our recordings (messages replayed byte for byte) and ROS 2 / ROS 1 MCAP files
  (sensor_msgs/PointCloud2 converted; other channels skipped with one warning each);
- ``*.bag`` (ROS 1), ``*.db3`` (ROS 2), a folder with ``metadata.yaml`` (ROS 2 bag): PointCloud2
  topics converted, via rosbags;
- a folder of simulator frames ``frame_*.npz`` (points, sensor_pose 4x4, stamp): clouds in the
  sensor frame (``lidar``) with the sensor pose, at their stamps;
- a folder of cloud files (.ply .pcd .xyz .txt .csv .npy .npz .obj, read with `read_cloud`),
  in name order, ``hz`` per second.

Each `SourceMessage` carries wire frames ready to publish and the time that drives replay
(receive time for recordings, bag time for bags, stamps or file order for folders).
"""

from __future__ import annotations

import os
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any

from supportnode.errors import ProtocolError, SupportNodeError
from supportnode.io.folder_source import FolderSource
from supportnode.io.recording import McapFile, RecordingError
from supportnode.io.source_base import Source, SourceMessage

__all__ = [
    "FolderSource",
    "McapSource",
    "RosbagSource",
    "Source",
    "SourceMessage",
    "open_source",
]


# ------------------------------------------------------------------------------------- MCAP


class McapSource(Source):
    """An MCAP file: our messages as recorded, ROS PointCloud2 channels converted."""

    kind = "mcap"

    def __init__(self, path: str | os.PathLike[str]) -> None:
        super().__init__(path)
        self.file = McapFile(self.path)
        self._t0: float | None = None
        self._seq: dict[str, int] = {}

    @property
    def warnings(self) -> list[str]:  # type: ignore[override]
        return self.file.warnings + self._own

    @warnings.setter
    def warnings(self, value: list[str]) -> None:
        self._own = value

    def _playable(self, ch: object) -> str | None:
        """Our type name or 'PointCloud' for a channel we can play, else None (warned)."""
        from supportnode.io.recording import ChannelInfo
        from supportnode.io.rosbag import POINTCLOUD2_TYPES

        assert isinstance(ch, ChannelInfo)
        if ch.is_supportnode:
            return ch.type
        if ch.schema_name in POINTCLOUD2_TYPES and ch.message_encoding in ("cdr", "ros1"):
            return "PointCloud"
        self.warn_once(
            f"skip:{ch.id}",
            f"{self.path}: topic {ch.topic!r} skipped ({ch.schema_name or 'no schema'} in "
            f"{ch.message_encoding or 'no encoding'}: only supportnode messages and "
            "sensor_msgs/PointCloud2 play)",
        )
        return None

    def topics(self) -> dict[str, str]:
        out: dict[str, str] = {}
        for ch in self.file.scan_channels().values():
            t = self._playable(ch)
            if t is not None:
                out[ch.topic] = t
        return out

    def start_time(self) -> float | None:
        if self._t0 is None:
            if self.file.stats.start_time is not None:
                self._t0 = self.file.stats.start_time * 1e-9
            else:
                first = next(iter(self.file.messages()), None)
                self._t0 = None if first is None else first.log_time * 1e-9
        return self._t0

    def duration(self) -> float | None:
        st = self.file.stats
        if st.start_time is None or st.end_time is None:
            return None
        return (st.end_time - st.start_time) * 1e-9

    def count(self, topic: str) -> int | None:
        counts = self.file.stats.channel_counts
        ids = [c.id for c in self.file.channels.values() if c.topic == topic]
        if not self.file.indexed or not all(i in counts for i in ids):
            return None
        return sum(counts[i] for i in ids)

    def messages(
        self,
        topics: Collection[str] | None = None,
        start: float = 0.0,
        duration: float | None = None,
    ) -> Iterator[SourceMessage]:
        begin, end = self._window(start, duration)
        if begin is None:
            return
        lo = None if start <= 0 else round(begin * 1e9)
        hi = None if end is None else round(end * 1e9)
        for raw in self.file.messages(topics, lo, hi):
            ch = raw.channel
            type_name = self._playable(ch)
            if type_name is None:
                continue
            try:
                if ch.is_supportnode:
                    frames = raw.frames()
                    stamp = raw.publish_time * 1e-9
                else:
                    frames, stamp = self._convert(raw.data, ch.message_encoding, ch.topic)
            except (SupportNodeError, ValueError) as err:
                self.warn_once(f"bad:{ch.id}", f"{self.path}: topic {ch.topic!r}: {err} (skipped)")
                continue
            yield SourceMessage(raw.log_time * 1e-9, stamp, ch.topic, type_name, frames)

    def _convert(self, data: bytes, encoding: str, topic: str) -> tuple[list[Any], float]:
        from supportnode.io.rosbag import deserialize_pointcloud2, pointcloud2_to_cloud

        seq = self._seq.get(topic, 0)
        self._seq[topic] = seq + 1
        notes: list[str] = []
        cloud = pointcloud2_to_cloud(
            deserialize_pointcloud2(data, encoding), seq=seq, warnings=notes
        )
        for note in notes:
            self.warn_once(f"note:{topic}:{note}", f"{self.path}: topic {topic!r}: {note}")
        return list(cloud.encode(topic)), cloud.stamp

    def close(self) -> None:
        self.file.close()


# --------------------------------------------------------------------------------- ROS bags


class RosbagSource(Source):
    """A ROS 1 or ROS 2 bag: its PointCloud2 topics as PointCloud messages (needs rosbags).

    When the bag has ``/tf`` (``tf2_msgs/TFMessage``), each scan gets its pose in
    ``fixed_frame`` (None: the root of the tree) at its stamp, and its gravity from
    ``sensor_msgs/Imu`` near rest; a scan without a transform within ``tf_tolerance`` s is
    skipped and counted in ``skipped`` ("tf missing", "tf late")."""

    kind = "rosbag"

    def __init__(
        self,
        path: str | os.PathLike[str],
        fixed_frame: str | None = None,
        tf_tolerance: float = 0.1,
    ) -> None:
        super().__init__(path)
        from supportnode.io.rosbag import IMU_TYPES, POINTCLOUD2_TYPES, TF_TYPES, RosBag

        self.bag = RosBag(self.path)
        self._clouds = {t for t, (typ, _) in self.bag.topics.items() if typ in POINTCLOUD2_TYPES}
        self.poser = self.bag.poser(fixed_frame, tf_tolerance)
        used = self._clouds | {
            t for t, (typ, _) in self.bag.topics.items() if typ in TF_TYPES | IMU_TYPES
        }
        for t, (typ, _) in sorted(self.bag.topics.items()):
            if t not in used:
                self.warn_once(
                    f"skip:{t}",
                    f"{self.path}: topic {t!r} skipped ({typ}: only sensor_msgs/PointCloud2 plays)",
                )

    def topics(self) -> dict[str, str]:
        return dict.fromkeys(sorted(self._clouds), "PointCloud")

    def start_time(self) -> float | None:
        return None if self.bag.start_time is None else self.bag.start_time * 1e-9

    def duration(self) -> float | None:
        if self.bag.start_time is None or self.bag.end_time is None:
            return None
        return max(0.0, (self.bag.end_time - self.bag.start_time) * 1e-9)

    def count(self, topic: str) -> int | None:
        return self.bag.topics[topic][1] if topic in self._clouds else 0

    def messages(
        self,
        topics: Collection[str] | None = None,
        start: float = 0.0,
        duration: float | None = None,
    ) -> Iterator[SourceMessage]:
        from supportnode.io.rosbag import PointCloud2Error
        from supportnode.io.tf import TfError

        begin, end = self._window(start, duration)
        if begin is None:
            return
        wanted = self._clouds if topics is None else self._clouds & set(topics)
        seqs: dict[str, int] = {}
        lo = round(begin * 1e9)
        hi = None if end is None else round(end * 1e9)
        for m in self.bag.messages(wanted, lo, hi):
            seq = seqs.get(m.topic, 0)
            seqs[m.topic] = seq + 1
            notes: list[str] = []
            try:
                cloud = self.bag.pointcloud(m, seq=seq, warnings=notes)
                if self.poser is not None:
                    cloud = self.poser.apply(cloud)
                frames = list(cloud.encode(m.topic))
            except TfError as err:
                self.skipped[err.reason] = self.skipped.get(err.reason, 0) + 1
                self.warn_once(
                    f"tf:{err.reason}",
                    f"{self.path}: topic {m.topic!r}: scans skipped, {err.reason}: {err}",
                )
                continue
            except (PointCloud2Error, ProtocolError) as err:
                self.warn_once(f"bad:{m.topic}", f"{self.path}: topic {m.topic!r}: {err} (skipped)")
                continue
            for note in notes:
                self.warn_once(f"note:{m.topic}:{note}", f"{self.path}: topic {m.topic!r}: {note}")
            yield SourceMessage(m.log_time * 1e-9, cloud.stamp, m.topic, "PointCloud", frames)
        self.warnings.extend(w for w in self.bag.warnings if w not in self.warnings)

    def close(self) -> None:
        self.bag.close()


# ---------------------------------------------------------------------------------- folders


# -------------------------------------------------------------------------------- choosing


def open_source(
    path: str | os.PathLike[str],
    *,
    topic: str = "scan",
    hz: float = 10.0,
    frame_id: str = "map",
    fixed_frame: str | None = None,
    tf_tolerance: float = 0.1,
) -> Source:
    """The source for ``path``, chosen by extension or folder contents (see the module doc).

    ``topic``, ``hz``, ``frame_id``: for folders of clouds only; ``fixed_frame``,
    ``tf_tolerance``: for ROS bags with tf (see `RosbagSource`). Raises a SupportNodeError
    (RecordingError, RosbagError, ...) with one line when the path cannot be a source.
    """
    name = os.fspath(path)
    p = Path(name)
    if not p.exists():
        raise RecordingError(f"{name}: no such file or folder")
    if p.is_dir():
        if (p / "metadata.yaml").exists():
            return RosbagSource(p, fixed_frame, tf_tolerance)
        return FolderSource(p, topic=topic, hz=hz, frame_id=frame_id)
    ext = p.suffix.lower()
    if ext == ".mcap":
        return McapSource(p)
    if ext in (".bag", ".db3"):
        return RosbagSource(p, fixed_frame, tf_tolerance)
    raise RecordingError(
        f"{name}: unknown recording type {p.suffix!r} (expected .mcap, .bag, .db3, a ROS 2 bag "
        "folder or a folder of cloud files)"
    )
