"""Wall time of a fresh ``supportnode detect`` process on one cloud, numba's cache warm.

What a user waits for when they run the command on a file (issue 20: at most 0.55-0.72 s on
the 150,000-point shelf): interpreter start, imports, compiled kernels loaded from the cache,
reading, detecting, writing ``--out`` and exiting. One untimed run first (it compiles what the
cache lacks), then ``--runs`` timed ones; also the time of a process that only imports what
``detect`` imports, and of one with numba alone (import it, call one trivial kernel from the
cache: numba's floor in a one-shot process). ``--baseline REV``: the same detect run by turns
from a temporary worktree of REV (the issue's "today" was the last revision without numba,
435455f). ``--cold N``: also N runs on an empty numba cache (an install's first run) of the
detect and of a node's warm-up, the kernels compiled in child processes or in that process
itself (``SUPPORTNODE_PRECOMPILE=0``), by turns. Prints the tables and one JSON line (medians, s)
for bench/ab.py; ``--docs`` writes the tables into docs/performance.md.

    python bench/bench_startup.py [--runs 5] [--align] [--baseline REV] [--cold N] [--docs]
                                  [CLOUD]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import docs_command, host_load, table, write_docs_block

from supportnode.kernels.precompile import usable_cores

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs" / "performance.md"
SHELF = REPO / "sim_scans" / "shelf_sampled.ply"
IMPORTS = "import supportnode.cli.detect, supportnode.pipeline, supportnode.io.results"
# numba's own floor in a one-shot process: import it and call one trivial kernel loaded from
# the cache, as supportnode's processes load theirs (`kernels.loading`: without the registries).
FLOOR_KERNEL = """import numba, numpy

@numba.njit(cache=True)
def total(a):
    return a.sum()
"""
FLOOR = (
    "import numpy, floor_kernel; from supportnode.kernels.loading import load_lightly; "
    "load_lightly(); floor_kernel.total(numpy.ones(3))"
)


# A user's Python caches the modules' bytecode; a developer's shell may forbid it
# (PYTHONDONTWRITEBYTECODE, set in some containers): every import would then compile the
# package's ~200 modules again (~0.1 s). The processes measured run as the user's would.
_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


_FLOOR_ROW = "numba alone"


def wall(cmd: list[str], source: Path | None = None, **extra: str) -> float:
    """Seconds from starting ``cmd`` to its exit (its output discarded); source: the tree
    whose package it runs (on PYTHONPATH and as the working directory), else this one's;
    extra: environment variables set for it."""
    env = dict(_ENV, **extra)
    if source is not None:
        env["PYTHONPATH"] = str(source)
    t = time.perf_counter()
    subprocess.run(
        cmd,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
        cwd=source,
    )
    return time.perf_counter() - t


# A node's warm-up before it subscribes (`supportnode run`'s), in a process of its own.
NODE_WARM_UP = (
    "from supportnode.node.rehearsal import warm_up; from supportnode.params import DetectParams;"
    " warm_up(DetectParams())"
)
# Row name -> (what runs, SUPPORTNODE_PRECOMPILE); "0": compiled in that process, as before.
_COLD_ROWS = {
    "detect, kernels compiled in child processes": ("detect", "1"),
    "detect, compiled in its own process": ("detect", "0"),
    "node warm-up, kernels compiled in child processes": ("node", "1"),
    "node warm-up, compiled in its own process": ("node", "0"),
}


def cold(detect: list[str], runs: int, times: dict[str, list[float]]) -> str:
    """A table of ``detect`` and of a node's warm-up on an empty numba cache (an install's
    first run), with and without the child processes that compile the kernels, by turns;
    each run's seconds are added to ``times`` under its row's name."""
    commands = {"detect": detect, "node": [sys.executable, "-c", NODE_WARM_UP]}
    times.update({k: [] for k in _COLD_ROWS})
    for _ in range(runs):
        for name, (what, switch) in _COLD_ROWS.items():
            with tempfile.TemporaryDirectory(prefix="bench-startup-cache-") as cache:
                times[name].append(
                    wall(commands[what], NUMBA_CACHE_DIR=cache, SUPPORTNODE_PRECOMPILE=switch)
                )
    rows = [
        [k, round(statistics.median(times[k]), 2), min(times[k]), max(times[k])] for k in _COLD_ROWS
    ]
    cores = usable_cores()
    head = f"numba's cache empty (an install's first run), {runs} runs, {cores} cores\n\n"
    return head + table(rows, ["process", "median s", "min s", "max s"])


def _is_commit(rev: str) -> bool:
    """Whether ``rev`` names a commit of this repository."""
    git = ["git", "-C", str(REPO), "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"]
    return subprocess.run(git, capture_output=True).returncode == 0


@contextlib.contextmanager
def worktree(rev: str | None) -> Iterator[Path | None]:
    """A temporary git worktree of ``rev`` (removed afterwards); None without a rev."""
    if rev is None:
        yield None
        return
    with tempfile.TemporaryDirectory(prefix="bench-startup-rev-") as tmp:
        path = Path(tmp) / "tree"
        git = ["git", "-C", str(REPO), "worktree"]
        subprocess.run([*git, "add", "--detach", str(path), rev], check=True, capture_output=True)
        try:
            yield path
        finally:
            subprocess.run([*git, "remove", "--force", str(path)], check=False)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cloud", nargs="?", default=str(SHELF), help="default: the shelf, 150k")
    ap.add_argument("--runs", type=int, default=5, help="timed runs of each (median)")
    ap.add_argument("--align", action="store_true", help="detect --align (a camera's cloud)")
    ap.add_argument("--docs", action="store_true", help=f"write the table into {DOCS}")
    ap.add_argument("--baseline", metavar="REV", help="also REV's detect, by turns")
    ap.add_argument("--cold", type=int, default=0, metavar="N", help="N runs on an empty cache")
    args = ap.parse_args()
    if args.runs < 1:
        ap.error(f"--runs must be at least 1, got {args.runs}")
    if args.cold < 0:
        ap.error(f"--cold must be at least 0, got {args.cold}")
    if not Path(args.cloud).is_file():
        ap.error(f"{args.cloud}: no such file")
    if args.baseline is not None and not _is_commit(args.baseline):
        ap.error(f"--baseline {args.baseline}: not a revision of {REPO}")
    load = os.getloadavg()
    cloud = str(Path(args.cloud).resolve())
    with (
        tempfile.TemporaryDirectory(prefix="bench-startup-") as out,
        worktree(args.baseline) as base,
    ):
        detect = [sys.executable, "-m", "supportnode", "detect", cloud, "--out", out]
        detect += ["--align"] if args.align else []
        sides = {"detect": None} | ({f"detect at {args.baseline}": base} if base else {})
        floor = Path(out) / "floor"
        floor.mkdir()
        (floor / "floor_kernel.py").write_text(FLOOR_KERNEL)
        for source in [*sides.values(), floor]:
            # fills numba's cache when it lacks a kernel, and bytecode's
            wall(detect if source is not floor else [sys.executable, "-c", FLOOR], source)
        times: dict[str, list[float]] = {k: [] for k in [*sides, "imports", _FLOOR_ROW]}
        for _ in range(args.runs):  # by turns: drift falls on all alike
            for name, source in sides.items():
                times[name].append(wall(detect, source))
            times["imports"].append(wall([sys.executable, "-c", IMPORTS]))
            times[_FLOOR_ROW].append(wall([sys.executable, "-c", FLOOR], floor))
        text = warm_table(times, args)
        if args.cold:
            text += "\n\n" + cold(detect, args.cold, times)
    print(text)
    print(json.dumps({"startup": {k: round(statistics.median(v), 4) for k, v in times.items()}}))
    if args.docs:
        command = docs_command("bench_startup.py", sys.argv[1:])
        write_docs_block(DOCS, "bench_startup", text, command, host_load(load))
    return 0


def warm_table(times: dict[str, list[float]], args: argparse.Namespace) -> str:
    """The warm runs' table: median, min and max of each process, seconds."""
    medians = {k: round(statistics.median(v), 4) for k, v in times.items()}
    rows = [[k, medians[k], min(v), max(v)] for k, v in times.items()]
    what = f"fresh processes on {Path(args.cloud).name}{' --align' if args.align else ''}"
    return f"{what}, {args.runs} runs, warm cache\n\n" + table(
        rows, ["process", "median s", "min s", "max s"]
    )


if __name__ == "__main__":
    sys.exit(main())
