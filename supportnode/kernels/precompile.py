"""A fresh install's kernels compiled on every core, once.

numba compiles one kernel at a time in a process, and all of supportnode's take tens of
seconds on one core, which the first command after an install (a ``supportnode detect``, a
node's warm-up) would wait for in full. When the kernel modules a process has imported lack cache entries
for several kernels (an empty cache, or a new numba), `compile_cold` starts child processes
that compile every kernel module into numba's cache (the same one: a child runs the same
package with the same environment), each taking the next module when it finishes one, waits
for them, and the caller then loads its kernels from the cache. A warm cache costs one look at
the index files of the modules already imported; a child that fails costs its time only (the
caller compiles whatever is still missing itself). Measured: ``bench/bench_startup.py --cold``.

``SUPPORTNODE_PRECOMPILE=0`` turns it off (1, the default, on; any other value is one
warning, and off). A child, ``python -m
supportnode.kernels.precompile``, compiles the kernel module named on each line of its stdin
and answers with the name: each child takes the next module when it finishes one.
"""

from __future__ import annotations

import importlib
import logging
import os
import pkgutil
import queue
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

_PACKAGE = "supportnode.kernels"
_NOT_KERNELS = frozenset({"runtime", "precompile", "loading"})
_SWITCH = "SUPPORTNODE_PRECOMPILE"  # "0" off, "1" on; "0" in the children (no grandchildren)
_MAX_WORKERS = 8  # each child holds numba and LLVM (~250 MB while compiling)
_MIN_COLD = 8  # fewer cold kernels than this compile faster in the process than in children
_DEADLINE_S = 900.0  # a child still compiling then is killed (all of them take ~40 s of CPU)

log = logging.getLogger("supportnode.kernels")


def kernel_modules() -> list[str]:
    """Names of the package's kernel modules (``"band"``, ...), sorted."""
    here = Path(__file__).resolve().parent
    return sorted(m.name for m in pkgutil.iter_modules([str(here)]) if m.name not in _NOT_KERNELS)


def _dispatchers(module: Any) -> list[Any]:
    """The module's own cached numba dispatchers, without those always inlined into their
    callers (numba never caches those on their own)."""
    from numba.core.dispatcher import Dispatcher

    return [
        obj
        for obj in vars(module).values()
        if isinstance(obj, Dispatcher)
        and obj.py_func.__module__ == module.__name__
        and obj.targetoptions.get("inline", "never") != "always"
        and getattr(obj, "_cache", None) is not None
    ]


def _cached(dispatcher: Any) -> bool:
    """Whether numba's cache holds an entry of ``dispatcher`` for this source (its index file
    exists and is not stale). numba has no public call for it: its cache file's index, read as
    numba reads it; anything unexpected counts as cached (no children are started for it)."""
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:  # another numba's internals: never a reason to compile in children
        return True


def cold_kernels(modules: Iterable[str]) -> dict[str, int]:
    """Per kernel module already imported (of ``modules``) whose first kernel lacks a cache
    entry, how many of its kernels do; the others left out (a warm-up compiles its module
    whole, so one look tells a warm cache: ~1 ms for a detect's modules; a module left half
    compiled compiles the rest in the caller, as without children). Imports nothing."""
    out = {}
    for name in modules:
        module = sys.modules.get(f"{_PACKAGE}.{name}")
        kernels = [] if module is None else _dispatchers(module)
        if not kernels or _cached(kernels[0]):
            continue
        out[name] = sum(not _cached(d) for d in kernels)
    return out


def _by_weight(names: Sequence[str]) -> list[str]:
    """``names`` heaviest first: each module's source size, which its compile time follows
    roughly (the longest ones first, so that no child starts one last)."""
    here = Path(__file__).resolve().parent

    def size(name: str) -> int:
        path = here / f"{name}.py"
        return path.stat().st_size if path.is_file() else 0

    return sorted(names, key=lambda m: (-size(m), m))


def usable_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def compile_cold(workers: int | None = None) -> int:
    """When the kernel modules imported so far lack cache entries for at least 8 kernels in 2
    modules or more (a fresh install), compile every kernel module in up to ``workers``
    (None: the usable cores; at most 8) child processes at once, each taking the next module
    as it finishes one; returns how many children ran (0: none were needed)."""
    switch = os.environ.get(_SWITCH, "1")
    if switch not in ("0", "1"):
        log.warning("%s=%r: expected 0 or 1; compiling in this process", _SWITCH, switch)
        return 0
    if switch == "0":
        return 0
    names = kernel_modules()
    cold = cold_kernels(names)
    n = min(usable_cores() if workers is None else workers, _MAX_WORKERS, len(names))
    if n < 2 or len(cold) < 2 or sum(cold.values()) < _MIN_COLD:
        return 0
    log.info("compiling the kernels in %d processes (once after an install)", n)
    t = time.perf_counter()
    todo: queue.SimpleQueue[str] = queue.SimpleQueue()
    for name in _by_weight(names):
        todo.put(name)
    threads = [threading.Thread(target=_child, args=(todo,), daemon=True) for _ in range(n)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    log.info("kernels compiled in %.1f s", time.perf_counter() - t)
    return n


def _command() -> list[str]:
    """A compiling child's command line."""
    return [sys.executable, "-m", __name__]


def _child(todo: queue.SimpleQueue[str]) -> None:
    """Feed modules from ``todo`` to one child, one at a time, until none are left; a child
    that fails is logged, never raised (the caller compiles what is still missing)."""
    env = dict(os.environ, **{_SWITCH: "0"})
    with tempfile.TemporaryFile("w+") as err:  # a file: a chatty child never blocks on it
        try:
            child = subprocess.Popen(
                _command(),
                env=env,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=err,
                text=True,
            )
        except OSError as exc:  # no interpreter to start (an embedded Python)
            log.warning("cannot start a child to compile kernels: %s", exc)
            return
        assert child.stdin is not None and child.stdout is not None
        # A child that hangs is killed: its stdout then ends, and the caller goes on.
        deadline = threading.Timer(_DEADLINE_S, child.kill)
        deadline.daemon = True
        deadline.start()
        try:
            while True:
                try:
                    name = todo.get_nowait()
                except queue.Empty:
                    break
                child.stdin.write(name + "\n")
                child.stdin.flush()
                if child.stdout.readline().strip() != name:  # it ended
                    break
            child.stdin.close()
        except OSError:  # its stdin closed: it ended
            pass
        child.wait()
        deadline.cancel()
        if child.returncode != 0:
            err.seek(0)
            last = err.read().strip().splitlines()[-1:] or ["no message"]
            log.warning(
                "a child compiling kernels failed (exit %s): %s; the rest compile here",
                child.returncode,
                last[0],
            )


def main(argv: Sequence[str]) -> int:
    """A child: compile the kernels (warm-ups) of each kernel module named on a line of stdin
    (or in ``argv``) into the cache, answering each with its name on stdout."""
    from supportnode.kernels import runtime

    runtime.configure()
    known = set(kernel_modules())
    lines = argv if argv else (line.strip() for line in sys.stdin)
    for name in lines:
        if name not in known:
            print(f"precompile: no kernel module {name!r}", file=sys.stderr)
            return 2
        importlib.import_module(f"{_PACKAGE}.{name}")
        runtime.warm_only([name])
        print(name, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
