"""What every offline source of scans is: `Source`, yielding `SourceMessage` (see
`supportnode.io.sources` for the kinds and how one is chosen)."""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field

from supportnode._closing import Closing
from supportnode.msgs import Limits, Message, decode_any

__all__ = ["Source", "SourceMessage"]


@dataclass
class SourceMessage:
    """One message of a source: ``time`` (s) drives replay timing, ``stamp`` (s) is the
    message's own; ``frames`` are wire frames ``[topic, header, *buffers]``."""

    time: float
    stamp: float
    topic: str
    type: str
    frames: list[bytes | memoryview] = field(repr=False)

    @property
    def size(self) -> int:
        """Bytes of all frames."""
        return sum(memoryview(f).nbytes for f in self.frames)

    def decode(self, limits: Limits | None = None) -> Message:
        """The decoded message (raises ProtocolError)."""
        return decode_any(self.frames, limits)


class Source(ABC, Closing):
    """A recording or folder to play. ``warnings``: one line per problem met so far."""

    kind: str = ""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = os.fspath(path)
        self.warnings: list[str] = []
        self._warned: set[str] = set()
        self.skipped: dict[str, int] = {}  # reason -> scans left out (e.g. "tf late")

    def warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.warnings.append(text)

    @abstractmethod
    def topics(self) -> dict[str, str]:
        """Topic -> message type of what `messages` yields (types after conversion)."""

    @abstractmethod
    def start_time(self) -> float | None:
        """Time of the first message, seconds (None: the source is empty)."""

    def duration(self) -> float | None:
        """Seconds from the first to the last message, when known without reading them all."""
        return None

    def count(self, topic: str) -> int | None:
        """Messages on ``topic``, when known without reading them all."""
        return None

    @abstractmethod
    def messages(
        self,
        topics: Collection[str] | None = None,
        start: float = 0.0,
        duration: float | None = None,
    ) -> Iterator[SourceMessage]:
        """Messages on ``topics`` (None: all) from ``start`` seconds after the first message,
        for ``duration`` seconds (None: to the end), in time order."""

    def _window(self, start: float, duration: float | None) -> tuple[float | None, float | None]:
        t0 = self.start_time()
        if t0 is None:
            return None, None
        begin = t0 + max(0.0, start)
        return begin, (None if duration is None else begin + duration)

    def close(self) -> None:  # sources without open files need no close
        """Release files (idempotent)."""
