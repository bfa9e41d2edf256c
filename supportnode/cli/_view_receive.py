"""`supportnode view`'s receiving side: subscriber threads that decode the node's topics and
hand (topic, message, receive time) to one consumer, and the command's output lines."""

from __future__ import annotations

import argparse
import sys
import threading
from typing import Any

from supportnode.cli._common import curve_keys, handshake_report

__all__ = ["Receiver", "ns", "receive", "say", "warn"]

# Results are small and every one matters for the deletions; of scans only the newest counts.
_KEEP_RESULTS = 16
_KEEP_SCANS = 1
_QUEUE = 64  # decoded messages waiting for conversion; beyond that the oldest waits in ZeroMQ


def warn(text: str) -> None:
    """One warning line on stderr."""
    print(f"supportnode view: warning: {text}", file=sys.stderr, flush=True)


def say(args: argparse.Namespace, text: str) -> None:
    """One progress line on stdout, unless ``--quiet``."""
    if not args.quiet:
        print(f"view: {text}", flush=True)


def ns(seconds: float) -> int:
    """Seconds -> nanoseconds (>= 0), as Foxglove logs times."""
    return max(0, round(seconds * 1e9))


def receive(args: argparse.Namespace, stop: threading.Event, handle: Any) -> None:
    """Subscribe to the node's topics (and the scans) and call ``handle(topic, message,
    receive time)`` for each until ``stop``, Ctrl-C or ``--duration``."""
    import queue
    import time

    inbox: queue.Queue[tuple[str, Any, float]] = queue.Queue(maxsize=_QUEUE)
    wanted = [(args.endpoint, args.topics, _KEEP_RESULTS)]
    if not args.no_scan:
        wanted.append((args.scan_endpoint, [args.scan_topic], _KEEP_SCANS))
    receivers: list[Receiver] = []
    deadline = None if args.duration is None else time.monotonic() + args.duration
    try:
        for i, (endpoint, topics, keep) in enumerate(wanted):
            curve = curve_keys(args, bind=False, index=i)
            receivers.append(Receiver(endpoint, topics, keep, inbox, stop, curve))
            receivers[-1].start()
        while not stop.is_set():
            if deadline is not None and time.monotonic() >= deadline:
                break
            try:
                topic, msg, received = inbox.get(timeout=0.1)
            except queue.Empty:
                continue
            handle(topic, msg, received)
    finally:
        stop.set()
        for r in receivers:
            r.join(2.0)
    rejected = sum(r.rejected for r in receivers)
    if rejected:
        last = next(r.last_error for r in receivers if r.last_error)
        say(args, f"{rejected} malformed messages skipped (last: {last})")


class Receiver(threading.Thread):
    """Subscribes to ``topics`` at ``endpoint`` and puts (topic, decoded message, receive time)
    into ``inbox`` until ``stop`` is set. The socket is opened in the caller's thread (so that a
    bad endpoint raises there) and used only by this thread afterwards."""

    def __init__(
        self,
        endpoint: str,
        topics: list[str],
        keep_newest: int,
        inbox: Any,
        stop: threading.Event,
        curve: Any = None,
    ) -> None:
        from supportnode import bus
        from supportnode.msgs import Limits

        super().__init__(daemon=True, name=f"view {endpoint}")
        self.limits = Limits()
        self.sub = bus.Subscriber(
            endpoint,
            topics,
            keep_newest=keep_newest,
            max_message_bytes=self.limits.max_message_bytes,
            curve=curve,
            watch=handshake_report("view"),
        )
        self.inbox, self.stop = inbox, stop
        self.rejected = 0
        self.last_error: str | None = None

    def run(self) -> None:
        import queue
        import time

        from supportnode.errors import ProtocolError
        from supportnode.msgs import decode_any

        try:
            while not self.stop.is_set():
                frames = self.sub.recv(0.1)  # short: notices `stop` soon
                if frames is None:
                    continue
                received = time.time()
                try:
                    msg = decode_any(frames, self.limits)
                except ProtocolError as err:
                    self.rejected += 1
                    self.last_error = str(err)
                    continue
                topic = bytes(memoryview(frames[0])).decode("utf-8", "replace")
                while not self.stop.is_set():
                    try:
                        self.inbox.put((topic, msg, received), timeout=0.1)
                        break
                    except queue.Full:
                        continue
        finally:
            self.sub.close()
