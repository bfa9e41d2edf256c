"""Where does an object fit? A planner's view of the node's results, printed live.

Subscribes to the node's SupportSurfaces and ObstacleClusters and, for every detection (the
two messages with the same ``seq``; the node sends the surfaces first), prints each safe
surface (id, height, free area, largest free disc) with "fits" or "does not fit" for an object
of footprint radius ``--radius``, then the obstacles standing on it. (A planner in a hurry can
act on the surfaces alone: their free space already keeps clear of the obstacles.)

    python examples/planner.py --endpoint tcp://127.0.0.1:5556 --radius 0.15

Ctrl-C (or SIGTERM, as `supportnode launch` sends) ends it with exit code 0.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from collections.abc import Sequence

from supportnode.client import Message, ObstacleClusters, Subscriber, SupportSurfaces


def fits(disc_radius: float, radius: float) -> str:
    """'fits', 'does not fit' or 'free space unknown' (the node sends NaN without free space)."""
    if math.isnan(disc_radius):
        return "free space unknown"
    return "fits" if disc_radius >= radius else "does not fit"


def report(surfaces: SupportSurfaces, obstacles: ObstacleClusters | None, radius: float) -> str:
    """The text printed for one SupportSurfaces message and the obstacles of its detection."""
    safe = [s for s in surfaces.surfaces if s.safe]
    lines = [
        f"seq {surfaces.seq} stamp {surfaces.stamp:.3f} frame {surfaces.frame_id}: "
        f"{len(safe)} safe of {len(surfaces.surfaces)} surfaces, object radius {radius:g} m"
    ]
    by_surface: dict[int | None, list[str]] = {}
    for c in obstacles.clusters if obstacles is not None else []:
        x, y, z = (float(v) for v in c.centroid)
        by_surface.setdefault(c.surface_id, []).append(
            f"#{c.id} at ({x:.2f}, {y:.2f}, {z:.2f}) {c.height:.2f} m tall"
        )
    for s in sorted(safe, key=lambda s: s.id):
        cx, cy = (float(v) for v in s.disc_center)
        disc = "none" if math.isnan(cx) else f"r {s.disc_radius:.3f} m at ({cx:.2f}, {cy:.2f})"
        lines.append(
            f"  surface {s.id}: height {s.height:.3f} m, free {s.free_area:.3f} of "
            f"{s.area:.3f} m^2, largest free disc {disc}: {fits(s.disc_radius, radius)}"
        )
        items = by_surface.get(s.id, [])
        lines.append(f"    obstacles: {', '.join(items) if items else 'none'}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--endpoint", default="tcp://127.0.0.1:5556", help="node's result socket")
    parser.add_argument("--surfaces-topic", default="surfaces")
    parser.add_argument("--obstacles-topic", default="obstacles")
    parser.add_argument("--radius", type=float, default=0.15, help="object footprint radius, m")
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    args = parser.parse_args(argv)

    # Sockets closed by the with block, exit code 0.
    # SIGINT and SIGTERM end it like Ctrl-C, also when it was started with SIGINT ignored
    # (a background job of a script): Python then leaves SIGINT ignored.
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.default_int_handler)
    topics = [args.surfaces_topic, args.obstacles_topic]
    surfaces: SupportSurfaces | None = None  # the newest, until its obstacles come
    obstacles: ObstacleClusters | None = None  # the newest

    def on_message(msg: Message) -> None:
        nonlocal surfaces, obstacles
        if isinstance(msg, ObstacleClusters):
            obstacles = msg
        elif isinstance(msg, SupportSurfaces):
            surfaces = msg
        # Whichever of a detection's two messages comes second completes it.
        if surfaces is not None and obstacles is not None and surfaces.seq == obstacles.seq:
            print(report(surfaces, obstacles, args.radius), flush=True)
            surfaces = None

    try:
        with Subscriber(topics, args.endpoint) as sub:
            print(f"planner: waiting for {', '.join(topics)} on {args.endpoint}", flush=True)
            sub.spin(on_message, args.duration)
            if sub.rejected:
                print(f"planner: {sub.rejected} malformed messages, last: {sub.last_error}")
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
