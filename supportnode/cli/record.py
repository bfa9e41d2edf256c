"""`supportnode record [TOPIC ...] -o FILE.mcap`: record what is published into an MCAP file.

Subscribes to the given topics (default: all) on the node's endpoints (default: the scan and
result endpoints of the configuration), and writes every message with its receive time and
stamp. Ctrl-C or SIGTERM finish the file; a killed recorder leaves a file readable up to its
last complete chunk (chunks are flushed every --flush seconds). Messages lost before they
reached us show as gaps in their sequence numbers: they are counted and reported at exit.

With --from SOURCE nothing is subscribed: the messages of a recording, ROS bag or folder of
clouds are written (converted) at their source times, e.g. to turn a bag into our MCAP.
"""

from __future__ import annotations

import argparse
from typing import Any

from supportnode.cli._common import (
    add_config_arguments,
    add_curve_arguments,
    curve_keys,
    handshake_report,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "topics", nargs="*", metavar="TOPIC", help="topics to record (default: all)"
    )
    parser.add_argument("-o", "--output", required=True, metavar="FILE.mcap", help="output file")
    parser.add_argument(
        "--endpoint",
        action="append",
        default=None,
        metavar="URL",
        help="endpoint to subscribe to (repeatable; default: node.scan_endpoint and "
        "node.pub_endpoint of the configuration)",
    )
    parser.add_argument(
        "--bind", action="store_true", help="bind the endpoints instead of connecting"
    )
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument(
        "--compression", choices=("zstd", "lz4", "none"), default="zstd", help="chunk compression"
    )
    parser.add_argument(
        "--chunk-size", type=float, default=4.0, metavar="MIB", help="chunk size, MiB (default 4)"
    )
    parser.add_argument(
        "--flush",
        type=float,
        default=1.0,
        metavar="S",
        help="close and flush a chunk at least every S seconds (what a hard kill can lose)",
    )
    parser.add_argument(
        "--queue",
        type=int,
        default=200,
        metavar="N",
        help="messages ZeroMQ may queue for us while a chunk is written (default 200: 10 s of "
        "2 MiB scans at 20 Hz)",
    )
    parser.add_argument(
        "--from",
        dest="source",
        metavar="SOURCE",
        help="convert a recording, ROS bag or folder of clouds instead of subscribing",
    )
    parser.add_argument("--topic", default="scan", help="--from a folder: its topic (default scan)")
    parser.add_argument("--hz", type=float, default=10.0, help="--from a folder of clouds: rate")
    parser.add_argument(
        "--frame-id", default="map", help="--from a folder of clouds: their frame (default map)"
    )
    parser.add_argument("--quiet", action="store_true", help="print only the summary and errors")
    add_config_arguments(parser, "node.scan_endpoint=tcp://127.0.0.1:6000")
    add_curve_arguments(parser)


def run(args: argparse.Namespace) -> int:
    import sys

    from supportnode.io.recording import RecordingWriter

    writer_args = {
        "compression": args.compression,
        "chunk_size": max(1, int(args.chunk_size * (1 << 20))),
        "flush_interval": args.flush,
    }
    if args.source is not None:
        return _convert(args, writer_args)
    endpoints = args.endpoint
    if not endpoints:
        from supportnode.config import load_config

        node = load_config(args.config, args.overrides).node
        endpoints = [node.scan_endpoint, node.pub_endpoint]
    import signal

    stop = {"now": False}

    def on_signal(signum: int, frame: object) -> None:
        # A flag, not an exception: the file must never be finished from inside a write. The
        # handlers stay until the file is finished, so a second signal cannot cut that short.
        stop["now"] = True

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        meta = {"endpoints": " ".join(endpoints)}
        with RecordingWriter(args.output, metadata=meta, **writer_args) as w:
            stats = _record(w, args, endpoints, stop)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    print(stats.summary(w), file=sys.stdout, flush=True)
    return 0


def _convert(args: argparse.Namespace, writer_args: dict[str, Any]) -> int:
    """--from: write a source's messages at their source times."""
    import sys

    from supportnode.io.recording import RecordingWriter
    from supportnode.io.sources import open_source

    with open_source(args.source, topic=args.topic, hz=args.hz, frame_id=args.frame_id) as src:
        topics = args.topics or None
        meta = {"converted_from": src.kind}
        with RecordingWriter(args.output, metadata=meta, **writer_args) as w:
            for m in src.messages(topics):
                w.write(m.frames, receive_time=m.time)
        for line in src.warnings:
            print(f"supportnode record: warning: {line}", file=sys.stderr)
    if not args.quiet:
        print(
            f"record: wrote {w.messages} messages ({_mb(sum(t.bytes for t in w.topics.values()))}) "
            f"on {', '.join(sorted(w.topics)) or 'no topics'} to {args.output}"
        )
    return 0


class _Stats:
    """Counters of a live recording."""

    def __init__(self) -> None:
        import time

        self.started = time.monotonic()
        self.rejected = 0  # not supportnode messages
        self.last_error = ""
        self.seqs: dict[str, Any] = {}  # topic -> SeqCounter

    def seq(self, topic: str, seq: int) -> None:
        from supportnode.msgs import SeqCounter

        self.seqs.setdefault(topic, SeqCounter()).observe(seq)

    @property
    def dropped(self) -> int:
        """Sequence gaps: lost before they reached us."""
        return sum(c.gaps for c in self.seqs.values())

    @property
    def restarts(self) -> int:
        """Sequences that went back or jumped far: a publisher restarted."""
        return sum(c.restarts for c in self.seqs.values())

    def summary(self, w: object) -> str:
        import time

        from supportnode.io.recording import RecordingWriter

        assert isinstance(w, RecordingWriter)
        elapsed = time.monotonic() - self.started
        per_topic = ", ".join(f"{t} {c.messages}" for t, c in sorted(w.topics.items()))
        text = (
            f"record: {w.messages} messages ({_mb(sum(c.bytes for c in w.topics.values()))}) in "
            f"{elapsed:.1f} s to {w.path} [{per_topic or 'none'}]; dropped {self.dropped} "
            "(sequence gaps)"
        )
        if self.restarts:
            text += f", {self.restarts} sequence restarts"
        if self.rejected:
            text += f", rejected {self.rejected} invalid (last: {self.last_error})"
        return text


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


def _record(
    w: object, args: argparse.Namespace, endpoints: list[str], stop: dict[str, bool]
) -> _Stats:
    """Receive until the duration is up or ``stop["now"]``; write each message as it arrives."""
    import sys
    import time

    import zmq

    from supportnode.bus import Tap
    from supportnode.io.recording import RecordingWriter

    assert isinstance(w, RecordingWriter)
    ctx = zmq.Context()
    topics = {t.encode() for t in args.topics}
    stats = _Stats()
    taps: list[Tap] = []
    poller = zmq.Poller()
    try:
        _open_taps(args, endpoints, topics, ctx, poller, taps)
        if not args.quiet:
            what = ", ".join(args.topics) or "all topics"
            print(
                f"record: recording {what} from {' '.join(endpoints)} to {w.path}",
                file=sys.stderr,
                flush=True,
            )
        deadline = None if args.duration is None else time.monotonic() + args.duration
        tty = sys.stderr.isatty() and not args.quiet
        next_progress = time.monotonic() + 1.0
        while not stop["now"]:
            if deadline is not None and time.monotonic() >= deadline:
                break
            w.tick()
            for tap in taps:
                tap.keep_connected()
            for sock, _ in poller.poll(100):
                _drain(sock, topics, w, stats)
            if tty and time.monotonic() >= next_progress:
                next_progress += 1.0
                print(f"\r{stats.summary(w)}", end="", file=sys.stderr, flush=True)
        if tty:
            print(file=sys.stderr)
    finally:
        for tap in taps:
            tap.close()
        ctx.term()
    return stats


def _open_taps(
    args: argparse.Namespace,
    endpoints: list[str],
    topics: set[bytes],
    ctx: Any,
    poller: Any,
    taps: list[Any],
) -> None:
    """A Tap per endpoint, appended to ``taps`` (closed by the caller, also after an error)
    and registered with ``poller``."""
    import zmq

    from supportnode.bus import Tap

    for i, ep in enumerate(endpoints):
        # Deep receive queue: ZeroMQ's I/O thread keeps receiving while we compress a
        # chunk. A socket per endpoint: each may have its own CURVE server key.
        taps.append(
            Tap(
                ep,
                sorted(topics),
                bind=args.bind,
                context=ctx,
                rcvhwm=max(1, args.queue),
                curve=curve_keys(args, args.bind, i),
                watch=handshake_report("record"),
            )
        )
        poller.register(taps[-1].socket, zmq.POLLIN)


def _drain(sock: object, topics: set[bytes], w: object, stats: _Stats) -> None:
    """Write what has arrived on ``sock`` (at most 10,000 messages: then the clock again)."""
    import time

    import zmq

    from supportnode.errors import ProtocolError
    from supportnode.msgs import peek_header

    assert isinstance(sock, zmq.Socket)
    for _ in range(10_000):
        try:
            parts = sock.recv_multipart(zmq.NOBLOCK, copy=False)
        except zmq.Again:
            return
        received = time.time()
        topic = parts[0].bytes
        if topics and topic not in topics:
            continue  # a prefix match (scan2 for scan)
        frames = [topic, *(p.buffer for p in parts[1:])]
        try:
            header = peek_header(frames, w.limits)  # type: ignore[attr-defined]
        except ProtocolError as err:
            stats.rejected += 1
            stats.last_error = str(err)
            continue
        w.write(frames, received, header)  # type: ignore[attr-defined]
        stats.seq(header.topic, header.seq)
