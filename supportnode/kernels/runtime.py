"""Numba's threading layer, thread count and kernel warm-up, decided in one place."""

from __future__ import annotations

import importlib
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

_WARMERS: list[Callable[[], None]] = []
_LOCK = threading.Lock()
_WARMED: set[Callable[[], None]] = set()  # warm-ups already run in this process
_configured = False


def warmer(fn: Callable[[], None]) -> Callable[[], None]:
    """Register ``fn`` (no arguments) to compile a module's kernels on tiny inputs."""
    _WARMERS.append(fn)
    return fn


def configure(threads: int | None = None) -> str:
    """Choose the threading layer and the number of threads of parallel kernels.

    numba's built-in ``workqueue`` layer aborts when two Python threads enter parallel kernels
    at once, and the node runs two threads: ask for a thread-safe layer (OpenMP or TBB). Where
    neither is available ``parallel_lock`` serialises parallel kernels instead. threads: None
    keeps numba's default (all cores). Returns the layer's name once a parallel kernel ran, or
    the requested policy before that.
    """
    global _configured
    import numba

    # numba.config sets its attributes at import time, from the environment: untyped.
    config: Any = numba.config
    with _LOCK:
        if not _configured:
            config.THREADING_LAYER = "threadsafe"
            _configured = True
        if threads is not None:
            numba.set_num_threads(max(1, min(int(threads), config.NUMBA_NUM_THREADS)))
    try:
        return str(numba.threading_layer())
    except ValueError:  # no parallel kernel has run yet
        return "threadsafe"


def warm(modules: Iterable[str] | None = None) -> float:
    """Run the warm-ups of the kernels in use; seconds taken (compile or cache load).

    modules: kernel module names (``"downsample"``, ...) to import first; None: only those
    already imported, i.e. the kernels the caller's code paths use (each user imports its
    kernel module when it is imported itself). Loading every kernel module would pay for
    kernels nobody calls (~1 s of a short ``supportnode detect``)."""
    t = time.perf_counter()
    configure()
    package = __package__ or "supportnode.kernels"
    for name in modules or ():
        importlib.import_module(f"{package}.{name}")
    with _LOCK:
        todo = [fn for fn in _WARMERS if fn not in _WARMED]
        _WARMED.update(todo)
    for fn in todo:
        fn()
    return time.perf_counter() - t
