"""`supportnode render RESULT_DIR`: draw a detect output folder as a PNG (needs the viz extra)."""

from __future__ import annotations

import argparse
from pathlib import Path

VIEWS = ("top", "side", "oblique")  # repeated from supportnode.render: keep --help import-light
COLORS = ("class", "id")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of the render subcommand."""
    parser.add_argument("result_dir", type=Path, help="output folder of `supportnode detect`")
    parser.add_argument(
        "-o",
        "--out",
        type=Path,
        metavar="PNG",
        help="picture to write (default: RESULT_DIR/result.png, result_<view>.png for other views)",
    )
    parser.add_argument("--view", choices=VIEWS, default="top", help="projection (default: top)")
    parser.add_argument(
        "--color",
        choices=COLORS,
        default="class",
        help="class: surface red, the rest green (as the report); id: by surface/object id",
    )
    parser.add_argument(
        "--max-points",
        type=_positive_int,
        default=200_000,
        metavar="N",
        help="draw at most N points, a seeded random subset (default: 200000)",
    )
    parser.add_argument(
        "--dpi", type=_positive_float, default=100.0, metavar="D", help="dots per inch (100)"
    )
    parser.add_argument(
        "--size",
        type=_size,
        default=(1600, 1200),
        metavar="WxH",
        help="picture size in pixels (default: 1600x1200)",
    )
    parser.add_argument("--quiet", action="store_true", help="print nothing but errors")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not 0 < value < 10_000:  # also rejects nan and inf
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    try:
        w, h = (int(p) for p in parts)
    except ValueError:
        w = h = 0
    if not (200 <= w <= 20_000 and 150 <= h <= 20_000):
        raise argparse.ArgumentTypeError(
            f"expected WxH in pixels, at least 200x150 (e.g. 1600x1200), got {text!r}"
        )
    return w, h


def run(args: argparse.Namespace) -> int:
    """Draw and write the picture; 0 on success (errors are raised, the dispatcher prints)."""
    from supportnode.errors import SupportNodeError
    from supportnode.render import render_result

    if args.result_dir.suffix.lower() == ".mcap":
        raise SupportNodeError(f"{args.result_dir}: recordings cannot be rendered yet")
    out = args.out
    if out is None:
        name = "result.png" if args.view == "top" else f"result_{args.view}.png"
        out = args.result_dir / name
    path = render_result(
        args.result_dir,
        out,
        view=args.view,
        color=args.color,
        max_points=args.max_points,
        size=args.size,
        dpi=args.dpi,
    )
    if not args.quiet:
        print(f"wrote {path}")
    return 0
