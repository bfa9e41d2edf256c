"""`supportnode launch FILE`: start the processes of a launch file and supervise them."""

from __future__ import annotations

import argparse

from supportnode.cli._common import positive_seconds


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "file",
        help="launch file (YAML list of processes), or the name of a shipped one: demo, "
        "example_pubsub (see: supportnode config list)",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="configuration override passed on to every 'supportnode' process as --set "
        "KEY=VALUE, e.g. --set node.detection_rate=2 (repeatable; other programs get none)",
    )
    parser.add_argument(
        "--stop-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="seconds a process gets to exit after SIGTERM before SIGKILL (default 5)",
    )
    parser.add_argument(
        "--duration",
        type=positive_seconds,
        metavar="S",
        help="stop everything after S seconds and exit 0 (default: run until Ctrl-C)",
    )
    parser.add_argument(
        "--check", action="store_true", help="only check the file and print the command lines"
    )


def run(args: argparse.Namespace) -> int:
    import shlex

    from supportnode.config import parse_override
    from supportnode.launch import Launcher, load_launch

    for text in args.overrides:
        parse_override(text)  # a malformed override fails here, not in every child
    launch = load_launch(_launch_path(args.file))
    if args.check:
        for spec in launch.processes:
            print(f"{spec.name}: {shlex.join(spec.argv(args.overrides))}")
        return 0
    launcher = Launcher(launch, args.overrides, stop_timeout=args.stop_timeout)
    if args.duration is not None:
        import threading

        timer = threading.Timer(args.duration, launcher.stop)  # stop() is thread-safe
        timer.daemon = True
        timer.start()
    code = launcher.run()
    if launcher.output_gone:
        import os

        # Python flushes stdout and stderr at exit; into a closed pipe that prints an error.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
    return code


def _launch_path(text: str) -> str:
    """A path as given, or a shipped launch file's when ``text`` is a bare name of one."""
    import os

    if os.path.exists(text) or os.sep in text:
        return text
    from supportnode.share import find_shipped

    return str(find_shipped("launch", text))
