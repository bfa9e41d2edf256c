"""`supportnode play SOURCE`: publish a recording with its recorded timing.

SOURCE: our MCAP recording, a ROS 2 MCAP / .db3 bag or ROS 1 .bag (PointCloud2 topics converted),
or a folder of cloud files / simulator frames. A reader thread reads ahead (decompression,
conversion) while the main thread sends each message when it is due: recorded time offsets
divided by --rate, measured from one start instant, so that lateness never accumulates.
Ctrl-C or SIGTERM end playback cleanly (exit 0).
"""

from __future__ import annotations

import argparse
import queue
import threading
from typing import Any

from supportnode.cli._common import (
    add_config_arguments,
    add_curve_arguments,
    add_tf_arguments,
    curve_keys,
    handshake_report,
    tf_options,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "source", help="recording (.mcap .bag .db3), ROS 2 bag folder, or folder of clouds"
    )
    parser.add_argument(
        "--rate", type=_positive, default=1.0, metavar="R", help="speed factor (default 1)"
    )
    parser.add_argument("--loop", action="store_true", help="start again at the end, forever")
    parser.add_argument(
        "--start", type=float, default=0.0, metavar="S", help="skip the first S seconds"
    )
    parser.add_argument(
        "--duration", type=float, metavar="S", help="play S seconds (of recording time)"
    )
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics")
    parser.add_argument(
        "--remap",
        action="append",
        default=[],
        type=_remap,
        metavar="FROM:=TO",
        help="publish topic FROM as TO (repeatable), e.g. --remap /os_cloud_node/points:=scan",
    )
    parser.add_argument(
        "--endpoint", metavar="URL", help="where to publish (default: node.scan_endpoint)"
    )
    parser.add_argument(
        "--connect",
        action="store_true",
        help="connect instead of binding (default: bind, like a driver)",
    )
    parser.add_argument(
        "--wait",
        type=float,
        default=0.5,
        metavar="S",
        help="pause before the first message so that subscribers connect (default 0.5)",
    )
    parser.add_argument(
        "--restamp",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="set each message's stamp to the wall clock when sent (default: on with --loop, "
        "so that a looped replay's time keeps moving and the node's map is not reset)",
    )
    parser.add_argument("--topic", default="scan", help="folder of clouds: topic (default scan)")
    parser.add_argument(
        "--hz", type=_positive, default=10.0, help="folder of clouds: rate (default 10)"
    )
    parser.add_argument("--frame-id", default="map", help="folder of clouds: frame (default map)")
    parser.add_argument(
        "--read-ahead", type=int, default=64, metavar="N", help="messages read ahead (default 64)"
    )
    parser.add_argument(
        "--hwm", type=int, default=100, metavar="N", help="send queue per subscriber"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress, only the summary")
    add_config_arguments(parser, "node.scan_endpoint=tcp://127.0.0.1:6000")
    add_curve_arguments(parser)
    add_tf_arguments(parser)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _remap(text: str) -> tuple[str, str]:
    old, sep, new = text.partition(":=")
    if not sep or not old or not new:
        raise argparse.ArgumentTypeError(f"expected FROM:=TO, got {text!r}")
    return old, new


def run(args: argparse.Namespace) -> int:
    import signal

    from supportnode.io.sources import open_source

    if args.restamp is None:
        args.restamp = args.loop
    endpoint, bind = args.endpoint, not args.connect
    if endpoint is None:
        from supportnode.config import load_config

        node = load_config(args.config, args.overrides).node
        endpoint = node.scan_endpoint
        bind = not node.scan_bind and not args.connect  # the node binds: we connect to it
    stop = {"now": False}

    def on_signal(signum: int, frame: object) -> None:
        stop["now"] = True

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        folder = {"topic": args.topic, "hz": args.hz, "frame_id": args.frame_id}
        with open_source(args.source, **folder, **tf_options(args)) as src:
            return Player(src, args, stop).run(endpoint, bind)
    finally:
        for s, h in old.items():
            signal.signal(s, h)


class Player:
    """Reads a source ahead in a thread and publishes its messages on time."""

    def __init__(self, source: object, args: argparse.Namespace, stop: dict[str, bool]) -> None:
        from supportnode.io.sources import Source

        assert isinstance(source, Source)
        self.src = source
        self.args = args
        self.stop = stop
        self.remap = {f.encode(): t.encode() for f, t in args.remap}
        self.sent = 0
        self.bytes = 0
        self.lags: list[float] = []
        self.printed_warnings = 0

    def run(self, endpoint: str, bind: bool) -> int:
        import sys
        import time

        from supportnode.bus import Publisher

        args = self.args
        items, reader = self._start_reader()
        pub = Publisher(
            endpoint,
            bind=bind,
            hwm=args.hwm,
            curve=curve_keys(args, bind),
            watch=handshake_report("play"),
        )
        finished = False
        try:
            if not args.quiet:
                total = self.src.duration()
                length = f"{total:.1f} s" if total is not None else "unknown length"
                print(
                    f"play: {self.src.path} ({self.src.kind}, {length}) on {pub.endpoint} at "
                    f"{args.rate:g}x{' in a loop' if args.loop else ''}",
                    file=sys.stderr,
                    flush=True,
                )
            self._sleep_until(time.monotonic() + max(0.0, args.wait))
            finished = self._play(items, pub)
        finally:
            self.stop["now"] = True  # ends the reader thread
            reader.join(timeout=5)
            if finished and not pub.closed:
                # Let ZeroMQ hand the last messages to the subscribers before closing.
                pub.socket.close(linger=1000)
            pub.close()
        self._flush_warnings()
        print(self.summary(), flush=True)
        if self.sent == 0 and not self.stop.get("interrupted"):
            print("supportnode play: nothing to play", file=sys.stderr)
            return 1
        return 0

    def _start_reader(self) -> tuple[queue.Queue[Any], threading.Thread]:
        q: queue.Queue[Any] = queue.Queue(maxsize=max(1, self.args.read_ahead))
        args = self.args

        def put(item: object) -> bool:
            while not self.stop["now"]:
                try:
                    q.put(item, timeout=0.1)
                    return True
                except queue.Full:
                    continue
            return False

        def read() -> None:
            try:
                while True:
                    count = 0
                    for m in self.src.messages(args.topics, args.start, args.duration):
                        count += 1
                        if not put(m):
                            return
                    if not put(("end of pass", count)) or not args.loop or count == 0:
                        break
            except Exception as err:  # handed to the main thread, which reports it
                put(err)
            put(None)

        thread = threading.Thread(target=read, name="play-reader", daemon=True)
        thread.start()
        return q, thread

    def _sleep_until(self, when: float) -> None:
        import time

        while not self.stop["now"]:
            left = when - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(left, 0.05))

    def _play(self, q: queue.Queue[Any], pub: object) -> bool:
        """Publish until the source ends (True) or a signal comes (False)."""
        import sys
        import time

        from supportnode.bus import Publisher
        from supportnode.errors import SupportNodeError
        from supportnode.io.sources import SourceMessage

        assert isinstance(pub, Publisher)
        args = self.args
        rate = args.rate
        tty = sys.stderr.isatty() and not args.quiet
        progress_every = 0.5 if tty else 10.0
        next_progress = time.monotonic() + progress_every
        wall0: float | None = None
        t_last = 0.0
        offset = 0.0  # recording time added per finished loop pass
        pass_first: float | None = None
        self.t_play = 0.0
        while not self.stop["now"]:
            try:
                item = q.get(timeout=0.1)
            except queue.Empty:
                continue
            if item is None:
                return True
            if isinstance(item, BaseException):
                if isinstance(item, SupportNodeError):
                    raise item
                raise SupportNodeError(f"{self.src.path}: {item}") from item
            if isinstance(item, tuple):  # end of one pass: the next starts one period later
                offset += self._pass_length(pass_first, t_last, item[1])
                pass_first = None
                continue
            assert isinstance(item, SourceMessage)
            if pass_first is None:
                pass_first = item.time
            if wall0 is None:
                wall0 = time.monotonic()
            t_last = item.time
            rel = item.time - pass_first + offset
            due = wall0 + rel / rate
            self._sleep_until(due)
            if self.stop["now"]:
                self.stop["interrupted"] = True
                return False
            pub.send(self._frames(item))
            now = time.monotonic()
            self.lags.append(now - due)
            self.sent += 1
            self.bytes += item.size
            self.t_play = rel
            if now >= next_progress and not args.quiet:
                next_progress = now + progress_every
                self._flush_warnings()
                end = "" if tty else "\n"
                print(f"\r{self.progress()}", end=end, file=sys.stderr, flush=True)
        self.stop["interrupted"] = True
        return False

    def _pass_length(self, first: float | None, last: float, n: int) -> float:
        """Recording time (s) one finished pass of ``n`` messages, stamped ``first`` to
        ``last``, takes up: its span and one period more; 0 for an empty pass."""
        if first is None or n <= 0:
            return 0.0
        span = last - first
        period = span / (n - 1) if n > 1 else 1.0 / self.args.hz
        return span + period

    def _frames(self, item: Any) -> list[Any]:
        """The frames of a recorded message as they go out: topic remapped, restamped now."""
        import time

        import msgpack

        frames = list(item.frames)
        topic = bytes(memoryview(frames[0]))
        if topic in self.remap:
            frames[0] = self.remap[topic]
        if self.args.restamp:
            header = msgpack.unpackb(frames[1], raw=False)
            header["stamp"] = time.time()
            frames[1] = msgpack.packb(header, use_bin_type=True)
        return frames

    def progress(self) -> str:
        total = self.src.duration()
        of = f" / {total:.1f}" if total is not None and not self.args.loop else ""
        return (
            f"play: {self.t_play:8.1f}{of} s  {self.sent} msgs  {self.bytes / 1e6:.1f} MB  "
            f"lag {1e3 * (self.lags[-1] if self.lags else 0):.1f} ms   "
        )

    def summary(self) -> str:
        import numpy as np

        lags = np.asarray(self.lags) * 1e3
        timing = (
            f"lag p50 {np.percentile(lags, 50):.1f} ms, p99 {np.percentile(lags, 99):.1f} ms, "
            f"max {lags.max():.1f} ms"
            if lags.size
            else "no timing"
        )
        return (
            f"\rplay: published {self.sent} messages ({self.bytes / 1e6:.1f} MB) covering "
            f"{self.t_play:.2f} s of recording at {self.args.rate:g}x; {timing}"
        )

    def _flush_warnings(self) -> None:
        import sys

        warnings = self.src.warnings
        for line in warnings[self.printed_warnings :]:
            print(f"supportnode play: warning: {line}", file=sys.stderr, flush=True)
        self.printed_warnings = len(warnings)
