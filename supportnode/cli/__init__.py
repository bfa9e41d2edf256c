"""The `supportnode` command: parses, dispatches to one module per subcommand, turns errors
into one line on stderr and an exit code (2 for bad input, 130 for Ctrl-C)."""

from __future__ import annotations

import argparse
import importlib
import re
import sys
from collections.abc import Sequence

from supportnode import __version__
from supportnode.cli import _process
from supportnode.errors import SupportNodeError

DESCRIPTION = """\
Find support surfaces (floors, table tops, shelf boards) and the objects standing on them in
point clouds: offline on files and recordings, or live as a ZeroMQ node beside your robot's
software."""

EXAMPLES = """\
examples:
  supportnode launch demo --duration 20         the live demo: a replayed lidar, the node, a planner
  supportnode detect scan.pcd --render          surfaces and objects of one cloud, into out/scan/
  supportnode detect run.mcap --every 5         every 5th scan of a recording (also .bag, .db3, folders)
  supportnode run --input run.mcap --output results.mcap   the node offline, as fast as it can
  supportnode run --config my.yaml              the node live: scans in on :5555, results out on :5556
  supportnode config dump -o my.yaml            every parameter with its default, unit and range

'supportnode COMMAND --help' tells a command's options; docs/cli.md has the details."""

# name -> (module, one-line help). Each module defines `add_arguments(parser)` and `run(args) -> int`;
# modules are imported only when their command runs, so optional extras stay optional.
COMMANDS: dict[str, tuple[str, str]] = {
    "detect": (
        "supportnode.cli.detect",
        "find support surfaces and objects in a cloud, or in every scan of a recording",
    ),
    "sim": ("supportnode.cli.sim", "simulate scenes with ground truth (sampled, lidar, camera)"),
    "eval": ("supportnode.cli.evaluate", "score a detect output against simulator ground truth"),
    "render": ("supportnode.cli.render", "draw a detection result as a PNG"),
    "launch": ("supportnode.cli.launch", "start a launch file's processes, stop them in order"),
    "run": (
        "supportnode.cli.run",
        "run the node: scans in, surfaces and obstacles out (--input REC: offline)",
    ),
    "record": ("supportnode.cli.record", "record published messages into an MCAP file"),
    "play": (
        "supportnode.cli.play",
        "publish a recording, ROS bag or cloud folder with its timing",
    ),
    "info": ("supportnode.cli.info", "topics, counts, rates and sizes of a recording or bag"),
    "echo": ("supportnode.cli.echo", "print a topic's messages, decoded (text or JSON lines)"),
    "hz": ("supportnode.cli.hz", "rate, period jitter and bandwidth of a topic, once a second"),
    "keys": ("supportnode.cli.keys", "make a CURVE key pair for encrypted, authenticated sockets"),
    "view": (
        "supportnode.cli.view",
        "show the node's topics or a recording live in Foxglove or Rerun",
    ),
    "config": ("supportnode.cli.config", "print the default configuration, list shipped files"),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; only ``command``'s module is imported (for its arguments), so one
    command's optional dependencies never stand in the way of another."""
    parser = argparse.ArgumentParser(
        prog="supportnode",
        description=DESCRIPTION,
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"supportnode {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_name, help_text) in COMMANDS.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        sp.set_defaults(_module=module_name)
        if name == command:
            importlib.import_module(module_name).add_arguments(sp)
    return parser


# "-0.6,0,1.2": a coordinate list starting with a minus, which argparse takes for an option.
_NEGATIVE_LIST = re.compile(r"^-[\d.][\d.eE+-]*(,\s*-?[\d.][\d.eE+-]*)+$")


def _join_negative_lists(argv: list[str]) -> list[str]:
    """``--sensor-origin -0.6,0,1.2`` as ``--sensor-origin=-0.6,0,1.2`` (what argparse needs)."""
    out: list[str] = []
    for arg in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and _NEGATIVE_LIST.match(arg):
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    if argv is None:  # the command line's: this process ends when main returns
        _process.process_entry()
    try:
        code = _main(argv)
    finally:
        _process.freeze()  # shutdown's collections skip what is left (~0.2 s after a detect)
    _process.end(code)  # when the command left nothing to finish: no shutdown at all
    return code


def _main(argv: Sequence[str] | None) -> int:
    argv = _join_negative_lists(list(sys.argv[1:] if argv is None else argv))
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(command if command in COMMANDS else None)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(importlib.import_module(args._module).run(args) or 0)
    except SupportNodeError as err:
        print(f"supportnode {args.command}: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `supportnode detect ... | head`: the reader has all it wants
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt as err:
        detail = getattr(err, "detail", "")  # cli._console.Interrupted: what was left behind
        print(
            f"supportnode {args.command}: interrupted" + (f" {detail}" if detail else ""),
            file=sys.stderr,
        )
        return 130


if __name__ == "__main__":
    sys.exit(main())
