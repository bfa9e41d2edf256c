"""`supportnode config dump [NAME] [-o FILE]`: a full configuration to start from."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    dump = sub.add_parser(
        "dump",
        help="print a configuration: every key with its default, unit and range",
        description="Print the full default configuration (or a shipped one) to edit and "
        "pass as --config. Example: supportnode config dump -o my.yaml",
    )
    dump.add_argument(
        "name",
        nargs="?",
        default="default",
        help="default (every key, generated), or a shipped file: noisy, report",
    )
    dump.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    sub.add_parser("list", help="the shipped configuration and launch files, with their paths")


def run(args: argparse.Namespace) -> int:
    from supportnode.share import find_shipped, share_dir

    if args.action == "list":
        root = share_dir()
        for kind in ("config", "launch"):
            for path in sorted((root / kind).glob("*.yaml")):
                print(f"{kind:<7} {path.stem:<16} {path}")
        return 0
    if args.name == "default":
        from supportnode.config import dump_default_yaml

        text = dump_default_yaml()
    else:
        text = find_shipped("config", args.name).read_text()
    if args.output:
        Path(args.output).write_text(text)
        print(f"wrote {args.output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
