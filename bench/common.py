"""Shared helpers for the benchmark scripts: timing medians and the simulator's clouds."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np


def median_time(fn: Callable[[], object], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def sampled_scene(name: str, n_points: int, seed: int = 0):
    """A noise-free sampled cloud of a bundled simulator scene (SimCloud)."""
    from supportnode.sim.scene import load_scene
    from supportnode.sim.sensors import sample_scene

    return sample_scene(load_scene(name), n_points, seed=seed)


def table(rows: list[list[object]], header: list[str]) -> str:
    """Plain-text table, columns right-aligned."""
    cells = [header] + [[_fmt(v) for v in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.3f}" if v < 100 else f"{v:.1f}"
    if isinstance(v, (int, np.integer)):
        return f"{v:,}"
    return str(v)
