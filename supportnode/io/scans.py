"""The scans of a recording or folder, one PointCloud after another: what `detect` on a
sequence and the offline node (`run --input`) read."""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from supportnode.errors import ProtocolError, SupportNodeError

if TYPE_CHECKING:  # `detect` on one cloud asks is_sequence only: no readers of recordings
    from supportnode.io.sources import Source
    from supportnode.msgs import PointCloud

__all__ = ["ScanSelection", "is_sequence"]

SEQUENCE_EXTENSIONS = (".mcap", ".bag", ".db3")


def is_sequence(path: str | os.PathLike[str]) -> bool:
    """A recording (.mcap .bag .db3) or a folder, not a single cloud file."""
    p = os.fspath(path)
    return os.path.isdir(p) or os.path.splitext(p)[1].lower() in SEQUENCE_EXTENSIONS


@dataclass
class ScanSelection:
    """Which scans of a source: the PointCloud ``topic`` (None: the only one, or ``scan``),
    every ``every``-th scan from ``start`` s after the first message for ``duration`` s."""

    topic: str | None = None
    every: int = 1
    start: float = 0.0
    duration: float | None = None
    skipped: dict[str, int] = field(default_factory=dict)  # reason -> scans left out

    def pick_topic(self, source: Source) -> str:
        clouds = sorted(t for t, typ in source.topics().items() if typ == "PointCloud")
        if self.topic is not None:
            if self.topic not in clouds:
                raise SupportNodeError(
                    f"{source.path}: no PointCloud topic {self.topic!r} "
                    f"(there are: {', '.join(clouds) or 'none'})"
                )
            return self.topic
        if len(clouds) == 1:
            return clouds[0]
        if "scan" in clouds:
            return "scan"
        raise SupportNodeError(
            f"{source.path}: "
            + (
                f"several PointCloud topics ({', '.join(clouds)}): pick one with --topic"
                if clouds
                else "no PointCloud topic to read scans from"
            )
        )

    def scans(self, source: Source, topic: str) -> Iterator[PointCloud]:
        """The selected scans, decoded; one that does not decode is skipped and counted, and
        so are those the source skipped (``skipped``, once the scans are all read)."""
        from supportnode.msgs import Limits, PointCloud

        limits = Limits()
        for i, m in enumerate(source.messages([topic], self.start, self.duration)):
            if i % self.every:
                continue
            try:
                msg = m.decode(limits)
            except ProtocolError as err:
                source.warn_once(f"decode:{topic}", f"{source.path}: topic {topic!r}: {err}")
                self.skipped["undecodable"] = self.skipped.get("undecodable", 0) + 1
                continue
            if isinstance(msg, PointCloud):
                yield msg
        for why, n in source.skipped.items():  # e.g. scans without a transform (ROS bags)
            self.skipped[why] = self.skipped.get(why, 0) + n

    def expected(self, source: Source, topic: str) -> int | None:
        """How many scans the selection will give, when the source knows its counts."""
        n = source.count(topic)
        if n is None or self.start > 0 or self.duration is not None:
            return None
        return -(-n // self.every)
