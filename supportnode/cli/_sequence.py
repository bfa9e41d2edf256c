"""Scan after scan through a recording, bag or folder, into results.mcap and results.jsonl:
the loop `detect` on a sequence and the offline node (`run --input`) share."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from supportnode.cli._common import add_tf_arguments, int_at_least, tf_options
from supportnode.cli._console import Interrupted, progress


def add_sequence_arguments(parser: argparse.ArgumentParser, title: str) -> None:
    """--topic, --every, --start and the tf options (``--duration`` is the command's own)."""
    group = parser.add_argument_group(title)
    group.add_argument("--topic", help="PointCloud topic to read (default: the only one, or scan)")
    group.add_argument(
        "--every", type=int_at_least(1), default=1, metavar="N", help="every N-th scan only"
    )
    group.add_argument(
        "--start", type=float, default=0.0, metavar="S", help="skip the first S seconds"
    )
    add_tf_arguments(parser)


def process_sequence(
    command: str,
    path: str,
    args: argparse.Namespace,
    output: Path,
    handle: Callable[[Any, Any], None],
) -> tuple[str, Any, Any]:
    """Call ``handle(scan, results)`` for each selected scan of ``path``, with progress;
    results go to ``output`` (MCAP) and the .jsonl beside it. Returns (topic, the finished
    `SequenceResults`, the `ScanSelection` with its skip counts). Ctrl-C raises `Interrupted`
    naming what was written; the source's warnings go to stderr."""
    from supportnode.io.scans import ScanSelection
    from supportnode.io.sequence import SequenceResults
    from supportnode.io.sources import open_source

    selection = ScanSelection(args.topic, args.every, args.start, args.duration)
    with open_source(path, **tf_options(args)) as source:
        topic = selection.pick_topic(source)
        total = selection.expected(source, topic)
        with (
            SequenceResults(output, output.with_suffix(".jsonl")) as results,
            progress(f"{command} {path}", total, "scans", args.quiet) as bar,
        ):
            try:
                for scan in selection.scans(source, topic):
                    handle(scan, results)
                    bar.advance(1)
            except KeyboardInterrupt as err:
                raise Interrupted(
                    f"after {results.scans} scans; their results are in "
                    f"{results.mcap_path} and {results.jsonl_path}"
                ) from err
        warnings = list(source.warnings)
    for w in warnings:
        print(f"supportnode {command}: warning: {w}", file=sys.stderr)
    return topic, results, selection
