"""`supportnode run --config config/default.yaml`: the node, until SIGINT/SIGTERM (exit 0).

With ``--input REC`` the node runs offline instead: every scan of a recording (or bag, or
folder) is merged into the map and detected, one after the other as fast as it goes, with no
sockets; the results go to ``--output`` (MCAP) and a JSON line per scan beside it. Scans are
processed in order and nothing is dropped, so the output is deterministic.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from supportnode.cli._common import (
    add_config_arguments,
    add_tf_arguments,
    int_at_least,
    positive_seconds,
    tf_options,
)
from supportnode.cli._console import Interrupted, print_table, progress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, "node.detection_rate=2")
    parser.add_argument(
        "--duration",
        type=positive_seconds,
        metavar="S",
        help="stop after S seconds (with --input: read S seconds of the recording from --start)",
    )
    parser.add_argument(
        "--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR")
    )
    offline = parser.add_argument_group("offline (no sockets)")
    offline.add_argument(
        "--input", metavar="REC", help="run on a recording, bag or folder instead of live"
    )
    offline.add_argument(
        "--output",
        metavar="FILE.mcap",
        default="results.mcap",
        help="offline results (default results.mcap; a .jsonl of one line per scan beside it)",
    )
    offline.add_argument("--topic", help="PointCloud topic of --input (default: the only one)")
    offline.add_argument(
        "--every", type=int_at_least(1), default=1, metavar="N", help="every N-th scan only"
    )
    offline.add_argument(
        "--start", type=float, default=0.0, metavar="S", help="skip the first S seconds"
    )
    offline.add_argument("--quiet", action="store_true", help="no progress or summary")
    add_tf_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from supportnode.config import load_config
    from supportnode.node.allocator import retain_freed_memory

    params = load_config(args.config, args.overrides)
    logging.basicConfig(
        stream=sys.stderr,
        level=getattr(logging, args.log_level),
        format=f"[{params.node.name}] %(levelname)s %(message)s",
    )
    retain_freed_memory()  # a node's working set repeats scan after scan: keep it mapped
    if args.input is not None:
        return _run_offline(args, params)
    return _run_live(args, params)


def _run_live(args: argparse.Namespace, params) -> int:
    from supportnode.node.node import Node

    # Sockets are opened inside spin and closed by the with block, also on SIGINT/SIGTERM,
    # which spin turns into a normal return (exit code 0).
    with Node(params) as node:
        node.spin(duration=args.duration)
        c = node.diagnostics().counters  # refreshes the socket's received / dropped counts
        logging.getLogger("supportnode.node").info(
            "stopped: %d scans received, %d processed, %d dropped, %d rejected; "
            "%d detections (%d of an unchanged map, reused), %d skipped for a newer scan",
            c["scans_received"],
            c["scans_processed"],
            c["scans_dropped"],
            c["scans_rejected"],
            c["detections"],
            c["detections_reused"],
            c["detections_skipped"],
        )
    return 0


def _run_offline(args: argparse.Namespace, params) -> int:
    import time

    from supportnode.errors import InputError
    from supportnode.io.scans import ScanSelection
    from supportnode.io.sequence import SequenceResults
    from supportnode.io.sources import open_source
    from supportnode.node.node import Node

    selection = ScanSelection(args.topic, args.every, args.start, args.duration)
    output = Path(args.output)
    t0 = time.perf_counter()
    detections = 0
    with open_source(args.input, **tf_options(args)) as source, Node(params) as node:
        topic = selection.pick_topic(source)
        with (
            SequenceResults(output, output.with_suffix(".jsonl")) as results,
            progress(
                f"run {args.input}", selection.expected(source, topic), "scans", args.quiet
            ) as bar,
        ):
            try:
                for scan in selection.scans(source, topic):
                    try:
                        out = node.process(scan)
                    except InputError:  # a scan without points: counted, the map unchanged
                        selection.skipped["empty"] = selection.skipped.get("empty", 0) + 1
                        continue
                    results.write(scan, out.surfaces, out.obstacles, out.timings)
                    detections += out.surfaces is not None
                    bar.advance(1)
            except KeyboardInterrupt as err:
                raise Interrupted(
                    f"after {results.scans} scans; their results are in "
                    f"{results.mcap_path} and {results.jsonl_path}"
                ) from err
        warnings = list(source.warnings)
    for w in warnings:
        print(f"supportnode run: warning: {w}", file=sys.stderr)
    if not args.quiet:
        rows = [("scans", results.scans), ("detections", detections)]
        rows += [(f"skipped: {why}", n) for why, n in selection.skipped.items()]
        rows.append(("seconds", f"{time.perf_counter() - t0:.2f}"))
        print_table((f"{args.input} (topic {topic})", ""), rows)
        print(f"wrote {results.mcap_path} and {results.jsonl_path}")
    return 0
