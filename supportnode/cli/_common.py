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


def add_curve_arguments(parser: argparse.ArgumentParser) -> None:
    """``--curve-key``, ``--curve-server-key`` (repeatable: one per endpoint, or one for all)
    and ``--curve-authorized``: CURVE keys of the command's sockets (see supportnode.curve)."""
    g = parser.add_argument_group("CURVE security (a node with node.curve_enabled)")
    g.add_argument(
        "--curve-key",
        metavar="FILE.key_secret",
        help="this side's key pair (supportnode keys); with it the sockets use CURVE",
    )
    g.add_argument(
        "--curve-server-key",
        action="append",
        default=[],
        metavar="FILE.key",
        help="public key of the server we connect to (the node's server.key; for the node's "
        "scan endpoint, the driver's): once for every endpoint, or once per --endpoint",
    )
    g.add_argument(
        "--curve-authorized",
        metavar="DIR",
        help="when binding: folder of the public keys (*.key) of the clients to accept",
    )


def curve_keys(args: argparse.Namespace, bind: bool, index: int = 0) -> Any:
    """The `supportnode.curve.CurveKeys` of the ``index``-th endpoint from the CURVE options,
    or None without ``--curve-key``; a one-line error for options that do not fit together."""
    from supportnode.curve import CurveKeys
    from supportnode.errors import BusError

    servers = args.curve_server_key
    if not args.curve_key:
        if servers or args.curve_authorized:
            raise BusError("--curve-server-key and --curve-authorized need --curve-key")
        return None
    if bind:
        if not args.curve_authorized:
            raise BusError("binding with --curve-key needs --curve-authorized DIR")
        return CurveKeys(args.curve_key, authorized_dir=args.curve_authorized)
    if not servers:
        raise BusError("connecting with --curve-key needs --curve-server-key FILE.key")
    if len(servers) > 1 and index >= len(servers):
        raise BusError(
            f"{len(servers)} --curve-server-key for more endpoints: give one for all, "
            "or one per endpoint in order"
        )
    return CurveKeys(args.curve_key, server_key=servers[index if len(servers) > 1 else 0])


def handshake_report(command: str) -> Any:
    """A report for `supportnode.bus` ``watch=``: why a socket hears nothing, on stderr."""
    import sys

    def report(line: str) -> None:
        print(f"supportnode {command}: {line}", file=sys.stderr, flush=True)

    return report


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
