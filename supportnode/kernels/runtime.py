"""Numba's threading layer, thread count and kernel warm-up, decided in one place."""

from __future__ import annotations

import importlib
import pkgutil
import threading
import time
from collections.abc import Callable

_WARMERS: list[Callable[[], None]] = []
_LOCK = threading.Lock()
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

    with _LOCK:
        if not _configured:
            numba.config.THREADING_LAYER = "threadsafe"
            _configured = True
        if threads is not None:
            numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    try:
        return str(numba.threading_layer())
    except ValueError:  # no parallel kernel has run yet
        return "threadsafe"


def warm() -> float:
    """Import every kernel module and run its warm-ups; seconds taken (compile or cache load)."""
    t = time.perf_counter()
    configure()
    package = importlib.import_module(__package__ or "supportnode.kernels")
    for info in pkgutil.iter_modules(package.__path__):
        if info.name != "runtime":
            importlib.import_module(f"{package.__name__}.{info.name}")
    for fn in list(_WARMERS):
        fn()
    return time.perf_counter() - t
