"""The package's `voxelize` (compiled kernels, a sort) against one plain numba loop over a dense grid.

Evidence for the node's latency work: the surfaces stage's voxel grid (10 x 10 x 5 cm: keys,
a counting sort, per-voxel moments) on the node's map after the moving OS-128 sequence of
``bench_node.py`` (kitchen_closed), timed against the simplest compiled version (a dense
cell array over the map's box, which only fits a box of modest size). It checks that both
give the same grid first.

    pip install -e ".[bench]" && python bench/bench_compiled.py [--scans 40] [--repeats 15]
"""

from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_node import moving_maps
from common import median_time, table

from supportnode.geometry.voxels import voxelize
from supportnode.params import DetectParams


def _compiled():
    import numba

    @numba.njit(cache=True)
    def voxelize_nb(p, size):
        n = p.shape[0]
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        k = np.empty((n, 3), np.int64)
        for i in range(n):
            for a in range(3):
                q = np.floor(p[i, a] / size[a])
                k[i, a] = np.int64(q)
                lo[a] = min(lo[a], q)
                hi[a] = max(hi[a], q)
        o = lo.astype(np.int64)
        d1 = np.int64(hi[1] - lo[1]) + 1
        d2 = np.int64(hi[2] - lo[2]) + 1
        cells = (np.int64(hi[0] - lo[0]) + 1) * d1 * d2
        lin = np.empty(n, np.int64)
        occupied = np.zeros(cells, np.int64)
        for i in range(n):
            c = ((k[i, 0] - o[0]) * d1 + (k[i, 1] - o[1])) * d2 + (k[i, 2] - o[2])
            lin[i] = c
            occupied[c] += 1
        rank = np.empty(cells, np.int64)
        m = 0
        for c in range(cells):
            if occupied[c]:
                rank[c] = m
                m += 1
        counts = np.zeros(m, np.int64)
        voxel = np.empty(n, np.int64)
        for i in range(n):
            v = rank[lin[i]]
            voxel[i] = v
            counts[v] += 1
        starts = np.empty(m, np.int64)
        s = 0
        for v in range(m):
            starts[v] = s
            s += counts[v]
        fill = starts.copy()
        order = np.empty(n, np.int64)
        for i in range(n):
            order[fill[voxel[i]]] = i
            fill[voxel[i]] += 1
        sums = np.zeros((m, 3))
        outer = np.zeros((m, 6))
        for j in range(n):
            i = order[j]
            v = voxel[i]
            x = p[i, 0] - k[i, 0] * size[0]
            y = p[i, 1] - k[i, 1] * size[1]
            z = p[i, 2] - k[i, 2] * size[2]
            sums[v, 0] += x
            sums[v, 1] += y
            sums[v, 2] += z
            outer[v, 0] += x * x
            outer[v, 1] += y * y
            outer[v, 2] += z * z
            outer[v, 3] += x * y
            outer[v, 4] += x * z
            outer[v, 5] += y * z
        return counts, order, sums, outer

    return voxelize_nb


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=40, help="moving OS-128 scans merged first")
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    if args.scans < 1 or args.repeats < 1:
        ap.error("--scans and --repeats must be at least 1")
    voxelize_nb = _compiled()
    _, m = collections.deque(moving_maps(args.scans), maxlen=1)[0]  # the last state
    pts = np.ascontiguousarray(m.points(), dtype=np.float64)
    size = np.asarray(DetectParams().surfaces.plane_voxel, dtype=np.float64)
    grid = voxelize(pts, size)
    counts, order, sums, outer = voxelize_nb(pts, size)
    same = np.array_equal(counts, grid.counts) and np.array_equal(order, grid.order)
    err = max(np.abs(sums - grid.sums).max(), np.abs(outer - grid.outer).max())
    t_np = 1e3 * median_time(lambda: voxelize(pts, size), args.repeats)
    t_nb = 1e3 * median_time(lambda: voxelize_nb(pts, size), args.repeats)
    print(
        table(
            [
                ["supportnode.geometry.voxels.voxelize", t_np, "reference"],
                [
                    "numba, one loop, dense grid",
                    t_nb,
                    f"same voxels: {same}, moments within {err:.1e}",
                ],
                ["ratio", t_np / t_nb, ""],
            ],
            [f"voxel grid of {len(pts):,} map points", "p50 ms", "result"],
        )
    )
    return 0 if same and err < 1e-9 else 1


if __name__ == "__main__":
    sys.exit(main())
