"""The node's receiving side: scans off the socket, merged; jobs to the detector; clearing.

A scan's free-space clearing (`NodeCore.settle`) runs once the surfaces of its job are out:
the job holds the map's points from before it, and the clearing then competes with the
detection's objects phase rather than with its surfaces. The detector rings a `Doorbell` when
surfaces go out, which ends the wait on the scan socket; a new scan ends it too (its merge
clears the previous scan first), and so does ``SETTLE_WAIT_S``."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from supportnode import bus
from supportnode.errors import SupportNodeError
from supportnode.node.admission import Admission
from supportnode.node.core import NodeCore
from supportnode.node.latency import LatencyWindow
from supportnode.node.mailbox import Doorbell, Mailbox
from supportnode.params import NodeParams

__all__ = ["Receiver"]

# The longest wait for the scan socket, s (stop and duration are checked this often).
POLL_S = 0.05
# A scan's clearing waits for its surfaces at most this long, s.
SETTLE_WAIT_S = 0.2


class Receiver:
    """The receiving thread's loop and state."""

    def __init__(
        self,
        core: NodeCore,
        sub: bus.Subscriber,
        wire: Admission,
        mailbox: Mailbox,
        bell: Doorbell,
        latency: LatencyWindow,
        cfg: NodeParams,
    ) -> None:
        self.core, self.sub, self.wire, self.cfg = core, sub, wire, cfg
        self.mailbox, self.bell, self.latency = mailbox, bell, latency
        self.unsettled: tuple[int, float] | None = None  # job number, deadline (monotonic)

    def run(
        self, stop: threading.Event, end: float | None, periodic: Callable[[float], float]
    ) -> None:
        """Receive until ``stop`` is set or ``end`` (monotonic s) passes. ``periodic(now)``
        runs after each wake-up (diagnostics, the map) and returns when it is due next."""
        due = periodic(time.monotonic())
        while not stop.is_set():
            now = time.monotonic()
            if end is not None and now >= end:
                break
            wait, wake = POLL_S, None
            if self.unsettled is not None:  # until the scan's surfaces are out
                wait, wake = max(0.0, self.unsettled[1] - now), self.bell.fileno()
            self.receive(min(wait, max(0.0, due - now)), wake)
            self.settle_when_due()
            due = periodic(time.monotonic())

    def receive(self, wait: float, wake: int | None) -> None:
        """Wait up to ``wait`` s for a scan (or ``wake``) and ingest it; oversized ones are
        rejected by count."""
        oversized = self.sub.oversized
        frames = self.sub.recv(wait, wake=wake)
        for _ in range(self.sub.oversized - oversized):
            size = self.sub.last_oversized[1] if self.sub.last_oversized else 0
            self.wire.reject(
                "oversized",
                f"message of {size} bytes exceeds max_message_bytes {self.cfg.max_message_bytes}",
            )
        if frames is not None:
            self.ingest(frames)

    def ingest(self, frames: Any) -> None:
        """Merge a decoded scan; its job, when due, to the mailbox."""
        msg, decode = self.wire.decoded(frames)
        if msg is None:
            return
        t_recv = time.perf_counter() - decode  # when decoding began
        self.mailbox.merging(True)  # a detector done with surfaces may wait for this one
        self.unsettled = None  # ingest clears the previous scan first
        try:
            job = self.core.ingest(msg)
            self.latency.add("decode", decode)
            if job is not None:
                self.latency.add_all(job.timings)
                job.timings.clear()  # timed here, once
                job.t_recv = t_recv
                number = self.mailbox.put(job)
                self.unsettled = (number, time.monotonic() + SETTLE_WAIT_S)
        except SupportNodeError as err:
            self.wire.reject("unusable", f"scan seq {msg.seq}: {err}")
        except Exception as err:
            self.wire.internal_error(f"scan seq {msg.seq}", err)
        finally:
            self.mailbox.merging(False)
        if self.unsettled is None:  # no detection to wait for
            self.settle()

    def settle_when_due(self) -> None:
        """The last scan's clearing, once its job's surfaces are out (or a newer job's), or
        SETTLE_WAIT_S after it was merged."""
        if self.unsettled is not None:
            number, deadline = self.unsettled
            # Rings so far taken back first, then the question: a ring for an older job (or
            # for this one, answered here) must not wake the next wait at once, again and
            # again; a ring after the question wakes it.
            self.bell.clear()
            if self.mailbox.surfaces_out(number) or time.monotonic() >= deadline:
                self.settle()

    def settle(self) -> None:
        """The last scan's clearing now."""
        self.unsettled = None
        try:
            self.latency.add("clear", self.core.settle())
        except Exception as err:
            self.wire.internal_error("clearing", err)
