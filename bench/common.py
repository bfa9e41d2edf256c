"""Shared helpers for the benchmark scripts: timing medians and the simulator's clouds."""

from __future__ import annotations

import os
import re
import statistics
import time
from collections.abc import Callable
from pathlib import Path

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


def write_docs_block(path: Path, name: str, text: str, command: str, load: str) -> None:
    """Replace the block between ``<!-- name: begin -->`` and ``<!-- name: end -->`` in ``path``
    with ``text`` (a table, fenced), the command that produced it and the host's load; the
    block is appended when the file does not hold it yet. Docs hold current figures only."""
    begin, end = f"<!-- {name}: begin -->", f"<!-- {name}: end -->"
    block = f"{begin}\n`{command}` (host load {load}):\n\n```\n{text}\n```\n{end}"
    doc = path.read_text(encoding="utf-8") if path.exists() else ""
    pattern = re.compile(f"{re.escape(begin)}.*?{re.escape(end)}", re.S)
    if pattern.search(doc):
        doc = pattern.sub(lambda _: block, doc)
    else:
        doc = doc.rstrip("\n") + ("\n\n" if doc else "") + block + "\n"
    path.write_text(doc, encoding="utf-8")


def docs_command(script: str, argv: list[str]) -> str:
    """The command line that reproduces a run, without ``--docs``."""
    return " ".join(["python", f"bench/{script}", *(a for a in argv if a != "--docs")])


def host_load(start: tuple[float, float, float]) -> str:
    """'A (1 min) at the start, B at the end' from ``os.getloadavg()`` taken at the start."""
    return f"{start[0]:.1f} (1 min) at the start, {os.getloadavg()[0]:.1f} at the end"
