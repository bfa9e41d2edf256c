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
from typing import Any

from supportnode.cli import _process
from supportnode.cli._common import add_config_arguments, positive_seconds
from supportnode.cli._console import print_table
from supportnode.cli._sequence import add_sequence_arguments, process_sequence


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
    offline.add_argument("--quiet", action="store_true", help="no progress or summary")
    add_sequence_arguments(parser, "offline: which scans of --input")


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
        node.spin(duration=args.duration, on_ready=_process.freeze)
        c = node.diagnostics().counters  # refreshes the socket's received / dropped counts
        logging.getLogger("supportnode.node").info(
            "stopped: %d scans received, %d processed, %d dropped, %d rejected; "
            "%d detections (%d of an unchanged map, reused), %d skipped for a newer scan, "
            "%d with their obstacles skipped for a newer scan's surfaces",
            c["scans_received"],
            c["scans_processed"],
            c["scans_dropped"],
            c["scans_rejected"],
            c["detections"],
            c["detections_reused"],
            c["detections_skipped"],
            c["obstacles_skipped"],
        )
    return 0


def _run_offline(args: argparse.Namespace, params) -> int:
    import time

    from supportnode.errors import InputError
    from supportnode.node.node import Node

    t0 = time.perf_counter()
    counts = {"detections": 0, "empty": 0}
    with Node(params) as node:

        def handle(scan: Any, results: Any) -> None:
            try:
                out = node.process(scan)
            except InputError:  # a scan without points: counted, the map unchanged
                counts["empty"] += 1
                return
            results.write(scan, out.surfaces, out.obstacles, out.timings)
            counts["detections"] += out.surfaces is not None

        topic, results, selection = process_sequence(
            "run", args.input, args, Path(args.output), handle
        )
    if not args.quiet:
        rows = [("scans", results.scans), ("detections", counts["detections"])]
        skipped = {**selection.skipped, "empty": counts["empty"]}
        rows += [(f"skipped: {why}", n) for why, n in skipped.items() if n]
        rows.append(("seconds", f"{time.perf_counter() - t0:.2f}"))
        print_table((f"{args.input} (topic {topic})", ""), rows)
        print(f"wrote {results.mcap_path} and {results.jsonl_path}")
    return 0
