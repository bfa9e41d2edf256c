"""Print one line per message on a topic: topic, type, seq, stamp and size.

    python examples/echo.py --endpoint tcp://127.0.0.1:5555 --topic scan

Ctrl-C (or SIGTERM) ends it with exit code 0.
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence

from supportnode.client import (
    Diagnostics,
    Message,
    ObstacleClusters,
    PointCloud,
    Subscriber,
    SupportSurfaces,
)


def describe(msg: Message) -> str:
    """What one message holds, in a few words."""
    if isinstance(msg, PointCloud):
        return f"{msg.count} points" + (" with pose" if msg.pose is not None else "")
    if isinstance(msg, SupportSurfaces):
        return f"{len(msg.surfaces)} surfaces"
    if isinstance(msg, ObstacleClusters):
        return f"{len(msg.clusters)} clusters"
    if isinstance(msg, Diagnostics):
        return f"{msg.node} {msg.level} {msg.message}".rstrip()
    return type(msg).__name__


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--endpoint", default="tcp://127.0.0.1:5555")
    parser.add_argument("--topic", action="append", help="topic (repeatable; default: scan)")
    parser.add_argument("--bind", action="store_true", help="bind instead of connecting")
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    args = parser.parse_args(argv)
    topics = args.topic or ["scan"]

    # SIGINT and SIGTERM end it like Ctrl-C, also when it was started with SIGINT ignored
    # (a background job of a script): Python then leaves SIGINT ignored.
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.default_int_handler)
    try:
        with Subscriber(topics, args.endpoint, bind=args.bind, keep_newest=10) as sub:

            def show(msg: Message) -> None:
                topic = "/".join(topics) if len(topics) > 1 else topics[0]
                print(
                    f"{topic} {type(msg).__name__} seq {msg.seq} stamp {msg.stamp:.3f} "
                    f"frame {msg.frame_id or '-'}: {describe(msg)}",
                    flush=True,
                )

            sub.spin(show, args.duration)
            if sub.rejected or sub.dropped:
                print(f"echo: {sub.rejected} rejected ({sub.last_error}), {sub.dropped} dropped")
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
