"""Arguments several commands share."""

from __future__ import annotations

import argparse
from typing import Any


def add_config_arguments(parser: argparse.ArgumentParser, example: str) -> None:
    """``--config YAML`` and repeatable ``--set KEY=VALUE`` (into ``args.overrides``).

    example: a typical override for this command's help text, e.g. ``surfaces.method=seed``."""
    parser.add_argument(
        "--config",
        metavar="YAML",
        help="configuration file; 'supportnode config dump -o my.yaml' writes every key "
        "with its default, unit and range to start from",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override one parameter, e.g. --set {example} (repeatable; after --config)",
    )


def _positive(text: str, what: str) -> float:
    import math

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a {what}, got {text}") from None
    if not value > 0 or not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a positive {what}, got {text}")
    return value


def positive_seconds(text: str) -> float:
    """argparse type: a finite number of seconds > 0."""
    return _positive(text, "number of seconds")


def positive_number(text: str) -> float:
    """argparse type: a finite number > 0 (a rate factor, a scale)."""
    return _positive(text, "number")


def int_at_least(low: int):
    """argparse type: an integer >= ``low``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {low}, got {value}")
        return value

    return parse


def add_tf_arguments(parser: argparse.ArgumentParser) -> None:
    """``--fixed-frame`` and ``--tf-tolerance``: poses of ROS bag scans from their /tf."""
    group = parser.add_argument_group("ROS bags with /tf")
    group.add_argument(
        "--fixed-frame",
        metavar="FRAME",
        help="frame the scans' poses are given in, e.g. odom or map (default: the tf tree's root)",
    )
    group.add_argument(
        "--tf-tolerance",
        type=positive_seconds,
        default=0.1,
        metavar="S",
        help="extrapolate a transform at most S seconds past its samples, else skip the scan "
        "(counted; default 0.1)",
    )


def tf_options(args: argparse.Namespace) -> dict[str, Any]:
    """The `open_source` keywords of `add_tf_arguments`."""
    return {"fixed_frame": args.fixed_frame, "tf_tolerance": args.tf_tolerance}


def add_rerun_arguments(parser: argparse.ArgumentParser, flag: str, what: str) -> None:
    """``flag`` [spawn|web] (show ``what`` in Rerun) and ``--save FILE.rrd``."""
    parser.add_argument(
        flag,
        nargs="?",
        const="spawn",
        choices=("spawn", "web"),
        help=f"show {what} in Rerun (needs the rerun extra): its viewer app (default), or "
        "'web': serve Rerun's web viewer from this machine and print its URL",
    )
    parser.add_argument("--save", metavar="FILE.rrd", help="write the Rerun scene to a file")
