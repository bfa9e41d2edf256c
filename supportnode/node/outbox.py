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

    Order: a detection's surfaces (with their free space) as soon as they are known, then
    its obstacles (same ``seq``) once the objects are split and described.
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

    def surfaces(self, out: NodeOutput, t_recv: float) -> None:
        """Send a detection's SupportSurfaces; time it, and receive -> surfaces sent."""
        assert out.surfaces is not None
        t = time.perf_counter()
        self.send(out.surfaces.encode(self._surfaces_topic))
        out.timings["publish"] = time.perf_counter() - t
        self._latency.add("receive_to_surfaces", time.perf_counter() - t_recv)

    def obstacles(self, out: NodeOutput, t_recv: float) -> None:
        """Send a detection's ObstacleClusters; time it, and receive -> both sent."""
        assert out.obstacles is not None
        t = time.perf_counter()
        self.send(out.obstacles.encode(self._obstacles_topic))
        out.timings["publish"] = out.timings.get("publish", 0.0) + time.perf_counter() - t
        self._latency.add("publish", out.timings["publish"])
        self._latency.add("receive_to_publish", time.perf_counter() - t_recv)

    def results(self, out: NodeOutput, t_recv: float) -> None:
        """Send both of a detection's messages, surfaces first."""
        self.surfaces(out, t_recv)
        self.obstacles(out, t_recv)

    def send_all(self, messages: Sequence[bus.Frames | Sequence[bytes]]) -> None:
        """Send whole messages one after the other, none of another thread in between."""
        with self._lock:
            for frames in messages:
                self.publisher.send(frames)

    def send(self, frames: bus.Frames | Sequence[bytes]) -> None:
        """Send one message (diagnostics, the map)."""
        self.send_all((frames,))
