"""Paired comparison of two revisions, or two configurations, on one benchmark script.

The shared 2-core host drifts by tens of percent within minutes, more than most changes are
worth, so runs made one after the other say little. This runs side A and side B by turns,
``--reps`` times each, and prints every number the script reports on its JSON lines
(flattened to dotted keys) as the median over A's runs, over B's, and the median of the paired
differences B - A (run k of B against run k of A).

    python bench/ab.py [--a REV] [--b REV] [--reps 3] [--keys p50,p99]
                       [--a-args "..."] [--b-args "..."] -- SCRIPT [ARGS ...]

REV: a git revision, checked out in a temporary worktree (removed afterwards), or "." for the
working tree as it is (the default of both sides). Each run uses its side's copy of SCRIPT and
of the package, on PYTHONPATH and as the working directory, so that what the script starts
(``python -m supportnode run``) runs that side's code too. --a-args, --b-args: arguments
added on one side only.

    python bench/ab.py --a HEAD~1 -- bench/bench_node.py --only e2e
    python bench/ab.py --b-args "--set node.threads=1" -- bench/bench_node.py --only e2e
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from common import table

REPO = Path(__file__).resolve().parent.parent


def flatten(obj: object, prefix: str = "") -> dict[str, float]:
    """The numbers of a JSON value by dotted key (list items by index); booleans left out."""
    out: dict[str, float] = {}
    if isinstance(obj, dict):
        for k, v in obj.items():
            out.update(flatten(v, f"{prefix}.{k}" if prefix else str(k)))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out.update(flatten(v, f"{prefix}.{i}"))
    elif isinstance(obj, int | float) and not isinstance(obj, bool):
        out[prefix] = float(obj)
    return out


def numbers(stdout: str) -> dict[str, float]:
    """All numbers of the JSON objects a benchmark printed, one per line."""
    out: dict[str, float] = {}
    for line in stdout.splitlines():
        if line.startswith("{"):
            out.update(flatten(json.loads(line)))
    return out


class Side:
    """One side of the comparison: a source tree and the arguments added to the script's."""

    def __init__(self, name: str, rev: str, extra: list[str], tmp: Path) -> None:
        self.name, self.rev, self.extra = name, rev, extra
        self.worktree: Path | None = None
        if rev == ".":
            self.tree = REPO
            return
        self.tree = tmp / name
        r = subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", "-q", str(self.tree), rev],
            capture_output=True,
            text=True,
        )
        if r.returncode != 0:
            raise SystemExit(f"ab.py: error: --{name} {rev}: {_last_line(r.stderr)}")
        self.worktree = self.tree

    def script(self, script: str) -> Path:
        """This side's copy of the script (a path inside the repository), or the script
        itself when it lies outside."""
        path = Path(script).resolve()
        try:
            return self.tree / path.relative_to(REPO)
        except ValueError:
            return path

    def run(self, script: str, args: list[str]) -> dict[str, float]:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(self.tree), str(self.tree / "bench"), env.get("PYTHONPATH")) if p
        )
        cmd = [sys.executable, str(self.script(script)), *args, *self.extra]
        r = subprocess.run(cmd, cwd=self.tree, env=env, capture_output=True, text=True)
        if r.returncode != 0:
            raise SystemExit(
                f"ab.py: error: side {self.name} ({self.rev}): {shlex.join(cmd)} exited with "
                f"{r.returncode}: {_last_line(r.stderr)}"
            )
        return numbers(r.stdout)

    def remove(self) -> None:
        if self.worktree is not None:
            subprocess.run(
                ["git", "-C", str(REPO), "worktree", "remove", "--force", str(self.worktree)],
                capture_output=True,
            )


def _last_line(text: str) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else "(no message)"


def compare(runs_a: list[dict[str, float]], runs_b: list[dict[str, float]], keys: list[str]):
    """Rows (key, median A, median B, median of B - A over the pairs, B / A) of the numbers
    that every run of both sides reported, filtered by substrings ``keys``."""
    common = set.intersection(*(set(r) for r in runs_a + runs_b))
    rows = []
    for k in sorted(common):
        if keys and not any(s in k for s in keys):
            continue
        a = [r[k] for r in runs_a]
        b = [r[k] for r in runs_b]
        ma, mb = statistics.median(a), statistics.median(b)
        diff = statistics.median(y - x for x, y in zip(a, b, strict=True))
        rows.append([k, ma, mb, diff, round(mb / ma, 3) if ma else float("nan")])
    return rows


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if "--" in argv:
        cut = argv.index("--")
        own, rest = argv[:cut], argv[cut + 1 :]
    else:
        own, rest = argv, []
    ap = argparse.ArgumentParser(
        prog="ab.py",
        description=__doc__.splitlines()[0],
        usage="%(prog)s [options] -- SCRIPT [ARGS ...]",
    )
    ap.add_argument("--a", default=".", metavar="REV", help='side A: a git revision or "."')
    ap.add_argument("--b", default=".", metavar="REV", help='side B: a git revision or "."')
    ap.add_argument("--a-args", default="", help="arguments for side A only (one string)")
    ap.add_argument("--b-args", default="", help="arguments for side B only (one string)")
    ap.add_argument("--reps", type=int, default=3, help="runs per side, taking turns")
    ap.add_argument("--keys", default="", help="show keys containing one of these (a,b,...)")
    args = ap.parse_args(own)
    if not rest:
        ap.error("no benchmark script: give it after --")
    if args.reps < 1:
        ap.error(f"--reps: expected at least 1, got {args.reps}")
    if not Path(rest[0]).is_file():
        ap.error(f"no such script: {rest[0]}")
    if shutil.which("git") is None:
        ap.error("git is needed to check out revisions")
    tmp = Path(tempfile.mkdtemp(prefix="supportnode-ab-"))
    sides: list[Side] = []
    try:
        for name, rev, extra in (("a", args.a, args.a_args), ("b", args.b, args.b_args)):
            sides.append(Side(name, rev, shlex.split(extra), tmp))
        runs: dict[str, list[dict[str, float]]] = {"a": [], "b": []}
        for k in range(args.reps):
            for side in sides:  # by turns: drift falls on both sides alike
                runs[side.name].append(side.run(rest[0], rest[1:]))
                print(f"run {k + 1}/{args.reps} {side.name} done", file=sys.stderr, flush=True)
        keys = [s for s in args.keys.split(",") if s]
        rows = compare(runs["a"], runs["b"], keys)
    finally:
        for side in sides:
            side.remove()
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"A = {args.a} {args.a_args}".rstrip() + f"; B = {args.b} {args.b_args}".rstrip())
    print(f"{args.reps} runs each, taking turns: {shlex.join(rest)}")
    if not rows:
        print("no numbers in common" + (f" matching {args.keys}" if keys else ""))
        return 1
    print(table(rows, ["key", "A median", "B median", "B - A (paired)", "B / A"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
