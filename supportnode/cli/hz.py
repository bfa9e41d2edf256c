"""`supportnode hz TOPIC`: message rate, period jitter and bandwidth of a topic, once a second.

Counts raw frames (nothing is decoded, malformed messages count too) on a plain SUB socket with
a deep receive queue, so a fast topic is measured as published rather than as a keep-newest
consumer would see it. Statistics are over the last ``--window`` messages: rate = (n - 1) /
(last arrival - first arrival), min/max/std of the periods between arrivals, and bandwidth =
bytes of those messages (all frames, topic included) / the same time span. Ends on Ctrl-C or
after ``--duration`` seconds (exit 0).
"""

from __future__ import annotations

import argparse
import itertools
import math
from collections.abc import Sequence

from supportnode.cli._common import (
    add_curve_arguments,
    curve_keys,
    handshake_report,
    int_at_least,
    positive_seconds,
)

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5556"
# Messages ZeroMQ may queue for us: deep enough that a busy moment never drops anything.
_RCVHWM = 10_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("topic", help="topic to measure, e.g. scan, surfaces")
    parser.add_argument(
        "--endpoint",
        default=DEFAULT_ENDPOINT,
        help=f"publisher endpoint to connect to (default {DEFAULT_ENDPOINT})",
    )
    parser.add_argument(
        "--window",
        type=int_at_least(2),
        default=100,
        metavar="N",
        help="statistics over the last N messages (default 100)",
    )
    parser.add_argument(
        "--duration",
        type=positive_seconds,
        metavar="S",
        help="stop after S seconds (default: until Ctrl-C)",
    )
    add_curve_arguments(parser)


def run(args: argparse.Namespace) -> int:
    import collections
    import sys
    import time

    import zmq

    from supportnode import bus

    topic = args.topic.encode()
    tap = bus.Tap(
        args.endpoint,
        [topic],
        rcvhwm=_RCVHWM,
        curve=curve_keys(args, bind=False),
        watch=handshake_report("hz"),  # says why nothing comes from a CURVE node
    )
    sock = tap.socket
    try:
        arrivals: collections.deque[float] = collections.deque(maxlen=args.window)
        sizes: collections.deque[int] = collections.deque(maxlen=args.window)
        start = time.monotonic()
        end = None if args.duration is None else start + args.duration
        next_report = start + 1.0
        total = 0
        reported_total = 0
        while True:
            now = time.monotonic()
            if end is not None and now >= end:
                break
            if now >= next_report:
                line = format_stats(arrivals, sizes) if total > reported_total else None
                print(line or f"no new messages (total {total})", flush=True)
                reported_total = total
                next_report += 1.0
                if next_report <= now:  # fell far behind (suspended): no catch-up burst
                    next_report = now + 1.0
                continue
            wake = next_report if end is None else min(next_report, end)
            tap.keep_connected()
            if not sock.poll(max(1, math.ceil((wake - now) * 1000)), zmq.POLLIN):
                continue
            while True:  # everything that has arrived, each stamped as it is taken
                try:
                    parts = sock.recv_multipart(zmq.NOBLOCK, copy=False)
                except zmq.Again:
                    break
                if parts[0].bytes != topic:
                    continue  # prefix match of another topic (scan2 for scan)
                arrivals.append(time.monotonic())
                sizes.append(sum(len(p) for p in parts))
                total += 1
                if time.monotonic() >= next_report:
                    break
    except KeyboardInterrupt:
        pass
    finally:
        tap.close()
    print(f"total {total} messages", file=sys.stderr, flush=True)
    return 0


def format_stats(arrivals: Sequence[float], sizes: Sequence[int]) -> str | None:
    """One report line over the window, or None with fewer than two messages."""
    if len(arrivals) < 2:
        return None
    times = list(arrivals)
    periods = [b - a for a, b in itertools.pairwise(times)]
    span = times[-1] - times[0]
    if span <= 0:
        return None
    mean = span / len(periods)
    std = math.sqrt(sum((p - mean) ** 2 for p in periods) / len(periods))
    window_bytes = sum(list(sizes)[1:])  # bytes that arrived during the span
    return (
        f"rate {len(periods) / span:.3f} Hz  period min {min(periods):.4f} s  "
        f"max {max(periods):.4f} s  std {std:.4f} s  window {len(times)}  "
        f"bandwidth {window_bytes / span / 1e6:.3f} MB/s  "
        f"({sum(sizes) / len(sizes) / 1e6:.3f} MB/msg)"
    )
