"""The node's one publishing socket and the order of what goes out on it."""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence

from supportnode import bus
from supportnode.node.core import NodeOutput
from supportnode.node.latency import LatencyWindow

__all__ = ["Outbox"]


class Outbox:
    """Owns the results `bus.Publisher`: the detecting thread sends results through it, the
    receiving thread diagnostics and the map; a ZeroMQ socket is not thread-safe, so each
    send holds the outbox's lock (sends take microseconds: nobody waits long).

    Order: a detection's obstacles, then its surfaces (same ``seq``), so a planner that reacts
    to surfaces already has their obstacles.
    """

    def __init__(
        self,
        publisher: bus.Publisher,
        topics: tuple[str, str],
        latency: LatencyWindow,
    ) -> None:
        self.publisher = publisher
        self._surfaces_topic, self._obstacles_topic = topics
        self._latency = latency
        self._lock = threading.Lock()

    def results(self, out: NodeOutput, t_recv: float) -> None:
        """Send a detection's messages; time encoding and sending, and receive -> sent."""
        assert out.surfaces is not None and out.obstacles is not None
        t = time.perf_counter()
        obstacles = out.obstacles.encode(self._obstacles_topic)
        surfaces = out.surfaces.encode(self._surfaces_topic)
        self.send_all((obstacles, surfaces))
        out.timings["publish"] = time.perf_counter() - t
        self._latency.add("publish", out.timings["publish"])
        done = time.perf_counter() - t_recv
        self._latency.add("receive_to_publish", done)
        self._latency.add("receive_to_surfaces", done)

    def send_all(self, messages: Sequence[bus.Frames | Sequence[bytes]]) -> None:
        """Send whole messages one after the other, none of another thread in between."""
        with self._lock:
            for frames in messages:
                self.publisher.send(frames)

    def send(self, frames: bus.Frames | Sequence[bytes]) -> None:
        """Send one message (diagnostics, the map)."""
        self.send_all((frames,))
