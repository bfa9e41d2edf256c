"""Arguments several commands share."""

from __future__ import annotations

import argparse


def add_config_arguments(parser: argparse.ArgumentParser, example: str) -> None:
    """``--config YAML`` and repeatable ``--set KEY=VALUE`` (into ``args.overrides``).

    example: a typical override for this command's help text, e.g. ``surfaces.method=seed``."""
    parser.add_argument(
        "--config", metavar="YAML", help="configuration file (see config/default.yaml)"
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override one parameter, e.g. --set {example} (repeatable; after --config)",
    )
