"""How local a moving scan's change to the node's map is: what a regional recompute could save.

On the moving OS-128 sequence of ``bench_node.py`` (kitchen_closed, noise-free), the map's
points are compared before and after each scan once the map has seen most of the room: the
points that appeared or went, and the share of all map points that lie in the x, y tiles
those touch, grown by the reach of detection's local rules. That share is what detection
would still have to redo if it recomputed only around the change (before any of the surfaces'
global rules are dealt with).

    python bench/bench_locality.py [--scans 60] [--from-scan 20] [--margin 0.5]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_node import moving_maps
from common import table


def _rows(points: np.ndarray) -> np.ndarray:
    """(N, 3) float64 -> (N,) void: one comparable value per point."""
    p = np.ascontiguousarray(points, dtype=np.float64)
    return p.view(np.dtype((np.void, 24))).ravel()


def changed(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """(K, 3) points in one map state and not in the other, metres."""
    a, b = _rows(before), _rows(after)
    return np.concatenate([after[~np.isin(b, a)], before[~np.isin(a, b)]])


def share_near(points: np.ndarray, change: np.ndarray, tile: float, margin: float) -> float:
    """Share of (N, 3) points in the tile x tile m columns that hold a changed point, grown by
    ``margin`` m (whole tiles, 8-connected)."""
    if not len(change):
        return 0.0
    lo = np.floor(points[:, :2].min(axis=0) / tile).astype(np.int64) - 1
    kp = np.floor(points[:, :2] / tile).astype(np.int64) - lo
    kc = np.floor(change[:, :2] / tile).astype(np.int64) - lo
    grid = np.zeros(kp.max(axis=0) + 2, dtype=bool)
    grid[kc[:, 0], kc[:, 1]] = True
    steps = int(np.ceil(margin / tile))
    if steps:
        grid = ndimage.binary_dilation(grid, structure=np.ones((3, 3)), iterations=steps)
    return float(grid[kp[:, 0], kp[:, 1]].mean())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=60, help="moving scans along the path")
    ap.add_argument("--from-scan", type=int, default=20, help="first scan compared")
    ap.add_argument("--margin", type=float, default=0.5, help="reach of local rules, m")
    args = ap.parse_args()
    if not 0 <= args.from_scan < args.scans - 1:
        ap.error("--from-scan must be at least 0 and below --scans - 1")
    if not (np.isfinite(args.margin) and args.margin >= 0):
        ap.error(f"--margin: expected a finite number >= 0, got {args.margin}")
    tiles = (0.25, 0.5, 1.0)
    counts, shares = [], {t: [] for t in tiles}
    previous = None
    for i, m in moving_maps(args.scans):
        pts = m.points().astype(np.float64)
        if previous is not None and i > args.from_scan:
            ch = changed(previous, pts)
            counts.append((len(ch), len(pts)))
            for t in tiles:
                shares[t].append(share_near(pts, ch, t, args.margin))
        previous = pts
    n_changed = np.median([c for c, _ in counts])
    n_points = np.median([n for _, n in counts])
    print(
        f"scans {args.from_scan + 1}-{args.scans - 1}: median {n_changed:.0f} of {n_points:.0f} "
        f"map points changed a scan ({100 * n_changed / n_points:.2f} %)\n"
    )
    rows = [
        [t, args.margin, 100 * np.median(shares[t]), 100 * np.percentile(shares[t], 90)]
        for t in tiles
    ]
    head = ["tile m", "margin m", "share of map points, median %", "p90 %"]
    print(table(rows, head))
    return 0


if __name__ == "__main__":
    sys.exit(main())
