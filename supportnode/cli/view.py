"""`supportnode view`: show the node's topics live in Foxglove or Rerun, or a recording.

    supportnode view                                   # live: subscribe, serve ws://127.0.0.1:8765
    supportnode view RECORDING.mcap                    # replay it to the viewer, recorded timing
    supportnode view RECORDING.mcap --out fox.mcap     # convert: an MCAP Foxglove opens directly
    supportnode view --rerun                           # live in Rerun's viewer (--rerun web: browser)
    supportnode view [RECORDING.mcap] --save run.rrd   # a Rerun file instead

Live, it subscribes to the node's results (``--endpoint``: surfaces, obstacles, diagnostics, map) and
to the scans (``--scan-endpoint``, unless ``--no-scan``), converts each message to Foxglove's
schemas (`supportnode.view.foxglove_bridge`) and forwards it to a Foxglove WebSocket server
running in this process; open the printed URL in a browser or the Foxglove desktop app. Ends on
Ctrl-C / SIGTERM or after ``--duration`` seconds (exit 0). Needs the ``view`` extra.
"""

from __future__ import annotations

import argparse
import sys
import threading
from typing import Any

from supportnode.cli._common import (
    add_curve_arguments,
    add_rerun_arguments,
    positive_number,
    positive_seconds,
)
from supportnode.cli._console import progress
from supportnode.cli._view_receive import ns, receive, say, warn

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5556"
DEFAULT_SCAN_ENDPOINT = "tcp://127.0.0.1:5555"
RESULT_TOPICS = ("surfaces", "obstacles", "diagnostics", "map")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's options (longer than ~60 lines: one declaration per option, read as a list)."""
    parser.add_argument(
        "source",
        nargs="?",
        help="a recording (.mcap from record or sim --out, ROS bag, cloud folder) to replay "
        "or, with --out, convert; none: view the running node live",
    )
    parser.add_argument(
        "--out",
        metavar="FILE.mcap",
        help="write SOURCE converted to Foxglove schemas to this MCAP file instead of serving",
    )
    parser.add_argument(
        "--endpoint",
        default=DEFAULT_ENDPOINT,
        help=f"the node's result endpoint (default {DEFAULT_ENDPOINT})",
    )
    parser.add_argument(
        "--topics",
        nargs="+",
        default=list(RESULT_TOPICS),
        metavar="TOPIC",
        help=f"result topics to show (default: {' '.join(RESULT_TOPICS)})",
    )
    parser.add_argument(
        "--scan-endpoint",
        default=DEFAULT_SCAN_ENDPOINT,
        help=f"where scans are published (default {DEFAULT_SCAN_ENDPOINT})",
    )
    parser.add_argument("--scan-topic", default="scan", help="scan topic (default scan)")
    parser.add_argument("--no-scan", action="store_true", help="do not show the scans")
    parser.add_argument(
        "--host", default="127.0.0.1", help="address the viewer server listens on (127.0.0.1)"
    )
    parser.add_argument(
        "--port",
        type=_port,
        default=8765,
        help="viewer server port (default 8765; 0: any free one)",
    )
    parser.add_argument(
        "--map-frame", default="map", help="frame the scans' poses lead to (default map)"
    )
    parser.add_argument(
        "--rate",
        type=positive_number,
        default=1.0,
        metavar="R",
        help="replay speed factor (default 1)",
    )
    parser.add_argument(
        "--duration", type=positive_seconds, metavar="S", help="stop after S seconds"
    )
    parser.add_argument("--quiet", action="store_true", help="print only errors")
    parser.add_argument(
        "--allow-origin",
        action="append",
        default=[],
        metavar="ORIGIN",
        help="also accept viewers from this web origin, e.g. https://studio.example.com "
        "(repeatable; '*': any). Default: the Foxglove app, localhost, the desktop app",
    )
    add_curve_arguments(parser)  # --curve-server-key: results' (node), then scans' (driver)
    add_rerun_arguments(parser, "--rerun", "the node (or SOURCE) instead of Foxglove")


def _port(text: str) -> int:
    """argparse type: a TCP port 0..65535."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {text}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be 0..65535, got {value}")
    return value


def run(args: argparse.Namespace) -> int:
    import signal

    from supportnode.view import ViewError, require_foxglove

    if args.rerun or args.save:
        return _rerun(args)
    require_foxglove()  # one line with the install command, before anything starts
    if args.out is not None and args.source is None:
        raise ViewError("--out converts a recording: give the recording too")
    if args.out is not None:
        return _convert(args)

    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _serve(args, stop)
    finally:
        for s, h in old.items():
            signal.signal(s, h)


# ----------------------------------------------------------------------------------- convert


def _convert(args: argparse.Namespace) -> int:
    """Write every message of ``args.source`` converted, at its recorded time."""
    import os

    import foxglove

    from supportnode.errors import ProtocolError
    from supportnode.io.sources import open_source
    from supportnode.view import ViewError
    from supportnode.view.foxglove_bridge import Bridge
    from supportnode.view.sink import Channels, write_mcap

    if os.path.exists(args.out) and os.path.samefile(args.out, args.source):
        raise ViewError(f"{args.out}: --out would overwrite the recording")
    bridge, skipped = Bridge(map_frame=args.map_frame), 0
    with open_source(args.source, topic=args.scan_topic) as src:
        ctx = foxglove.Context()
        channels = Channels(ctx)
        with (
            write_mcap(ctx, args.out) as writer,
            progress(f"view {args.source}", _count(src), "messages", args.quiet) as bar,
        ):
            writer.write_metadata("supportnode", {"converted_from": os.fspath(args.source)})
            for m in src.messages():
                bar.advance(1)
                try:
                    msg = m.decode()
                except ProtocolError as err:
                    skipped += 1
                    print(f"supportnode view: skipped: {err}", file=sys.stderr)
                    continue
                channels.log(bridge.convert(msg, m.topic), ns(m.time))
        for line in src.warnings:
            print(f"supportnode view: warning: {line}", file=sys.stderr)
    say(
        args,
        f"wrote {channels.logged} messages on {', '.join(channels.topics) or 'no topics'} "
        f"to {args.out}" + (f" ({skipped} skipped)" if skipped else ""),
    )
    return 0


def _count(src: Any) -> int | None:
    """Messages of every topic of ``src``, when it knows them without reading."""
    counts = [src.count(t) for t in src.topics()]
    return None if None in counts else sum(c for c in counts if c is not None)


# ------------------------------------------------------------------------------------- serve


def _serve(args: argparse.Namespace, stop: threading.Event) -> int:
    """Start the server, then forward live messages or replay ``args.source`` until done."""
    import foxglove

    from supportnode.view.foxglove_bridge import Bridge
    from supportnode.view.sink import Channels, serve

    ctx = foxglove.Context()
    server = serve(ctx, args.host, args.port, args.allow_origin, warn)
    channels = Channels(ctx)
    try:
        say(
            args,
            f"open {server.app_url(args.host)}  (or connect Foxglove to {server.ws_url(args.host)})",
        )
        if server.exposed:
            warn(
                "every port browsers cannot reach is in use: the Foxglove server listens on "
                f"127.0.0.1:{server.server.port}, where the origin check can be bypassed"
            )
        bridge = Bridge(map_frame=args.map_frame)
        if args.source is None:
            _live(args, stop, bridge, channels)
        else:
            _replay(args, stop, bridge, channels)
    finally:
        channels.close()
        server.stop()
    say(args, f"forwarded {channels.logged} messages")
    return 0


def _live(args: argparse.Namespace, stop: threading.Event, bridge: Any, channels: Any) -> None:
    receive(args, stop, lambda topic, msg, t: channels.log(bridge.convert(msg, topic), ns(t)))


def _replay(args: argparse.Namespace, stop: threading.Event, bridge: Any, channels: Any) -> None:
    """Forward ``args.source`` with its recorded timing divided by ``args.rate``: each message
    is due at its offset from the first, measured from one start instant (no drift)."""
    import time

    from supportnode.errors import ProtocolError
    from supportnode.io.sources import open_source

    with open_source(args.source, topic=args.scan_topic) as src:
        start = time.monotonic()
        end = None if args.duration is None else start + args.duration
        first: float | None = None
        for m in src.messages():
            first = m.time if first is None else first
            due = start + (m.time - first) / args.rate
            if end is not None and due >= end:
                break
            if stop.wait(max(0.0, due - time.monotonic())):
                break
            try:
                msg = m.decode()
            except ProtocolError as err:
                print(f"supportnode view: skipped: {err}", file=sys.stderr)
                continue
            # Receive time as it happens now: the viewer's clock runs with the replay.
            channels.log(bridge.convert(msg, m.topic), time.time_ns())
        for line in src.warnings:
            print(f"supportnode view: warning: {line}", file=sys.stderr)
    if not stop.is_set() and (end is None or time.monotonic() < end):
        # Keep serving, so that the last scene stays on screen until the user is done.
        say(args, "end of the recording; Ctrl-C to stop")
        stop.wait(None if end is None else max(0.0, end - time.monotonic()))


# ------------------------------------------------------------------------------------- rerun


def _rerun(args: argparse.Namespace) -> int:
    """The node's topics (or SOURCE's messages, as fast as they read) into a Rerun scene."""
    import signal

    from supportnode.view.rerun_scene import RerunScene

    stop = threading.Event()
    old = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with RerunScene("save" if args.save else args.rerun, args.save) as scene:
            if scene.url is not None:
                say(args, f"open {scene.url}")
            if args.source is None:
                counter = [0]

                def handle(topic: str, msg: Any, received: float) -> None:
                    scene.log_message(topic, msg)
                    counter[0] += 1

                receive(args, stop, handle)
                shown = counter[0]
            else:
                shown = _rerun_source(args, scene)
                if scene.url is not None:  # keep serving until the user is done
                    say(args, "end of the recording; Ctrl-C to stop")
                    stop.wait(args.duration)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    say(args, f"{shown} messages" + (f" written to {args.save}" if args.save else " shown"))
    return 0


def _rerun_source(args: argparse.Namespace, scene: Any) -> int:
    from supportnode.errors import ProtocolError
    from supportnode.io.sources import open_source

    shown = 0
    with open_source(args.source, topic=args.scan_topic) as src:
        for m in src.messages():
            try:
                scene.log_message(m.topic, m.decode())
            except ProtocolError as err:
                print(f"supportnode view: skipped: {err}", file=sys.stderr)
                continue
            shown += 1
        for line in src.warnings:
            print(f"supportnode view: warning: {line}", file=sys.stderr)
    return shown
