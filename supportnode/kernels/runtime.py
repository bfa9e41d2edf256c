"""Numba's threading layer, thread count and kernel warm-up, decided in one place."""

from __future__ import annotations

import ctypes
import importlib
import sys
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

_WARMERS: list[Callable[[], None]] = []
_LOCK = threading.Lock()
_WARMED: set[Callable[[], None]] = set()  # warm-ups already run in this process
_configured = False
_threads: int | None = None  # the budget configure() was given (None: all cores)
_precompile_tried = False  # whether warm() looked for a fresh install's empty cache yet


def warmer(fn: Callable[[], None]) -> Callable[[], None]:
    """Register ``fn`` (no arguments) to compile a module's kernels on tiny inputs."""
    _WARMERS.append(fn)
    return fn


# glibc's mallopt parameters, and the values kept: blocks up to this size come from the heap
# (not a fresh mapping each), and freed memory stays until this much lies free at its top.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20  # glibc's largest allowed
_TRIM_THRESHOLD = 256 << 20


def keep_freed_memory() -> bool:
    """Have glibc's allocator keep freed memory for the next allocations; whether it took.

    A detection allocates and frees tens of MB of (N,) arrays per cloud. By default glibc maps
    blocks above a threshold afresh and returns a freed heap top to the system, and it moves
    that threshold as it goes: depending on the process's history, every scan then faults
    in its arrays' pages again (up to ~3000 faults a 640 x 480 scan, ~1.7 us each on a VM:
    5 ms, 10 % of the detection) or none. Fixed thresholds keep the pages: the process keeps
    its peak memory instead. No-op off glibc. Process-wide: called by the processes that are
    supportnode's (the node's `warm_up`, ``supportnode detect``), never by the library on its
    own (a planner importing supportnode keeps its allocator as it set it)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = _libc()
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(
        mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD) and mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD)
    )


def _libc() -> ctypes.CDLL:
    """The C library: glibc's soname first (find_library runs ``ldconfig -p`` in a child
    process, ~1-2 ms of a detect), else whatever find_library names."""
    try:
        return ctypes.CDLL("libc.so.6")
    except OSError:
        from ctypes.util import find_library

        return ctypes.CDLL(find_library("c") or "libc.so.6")


def configure(threads: int | None = None) -> str:
    """Choose the threading layer and the number of threads of parallel kernels.

    numba's built-in ``workqueue`` layer aborts when two Python threads enter parallel kernels
    at once, and the node runs two threads: ask for a thread-safe layer (OpenMP or TBB). Where
    neither is available ``parallel_lock`` serialises parallel kernels instead. threads: None
    keeps numba's default (all cores). Returns the layer's name once a parallel kernel ran, or
    the requested policy before that.
    """
    global _configured, _threads
    import numba

    # numba.config sets its attributes at import time, from the environment: untyped.
    config: Any = numba.config
    with _LOCK:
        if not _configured:
            config.THREADING_LAYER = "threadsafe"
            _configured = True
        if threads is not None:
            _threads = max(1, min(int(threads), config.NUMBA_NUM_THREADS))
            # numba's count is the calling thread's own: each worker thread applies the
            # budget itself (apply_threads).
            numba.set_num_threads(_threads)
    try:
        return str(numba.threading_layer())
    except ValueError:  # no parallel kernel has run yet
        return "threadsafe"


def apply_threads() -> None:
    """Bound the calling thread's parallel kernels by the configured budget: numba's thread
    count is per thread, and :func:`configure` set only its caller's (a node's detecting
    thread calls this once it starts)."""
    if _threads is not None:
        import numba

        numba.set_num_threads(_threads)


def warm(modules: Iterable[str] | None = None) -> float:
    """Run the warm-ups of the kernels in use; seconds taken (compile or cache load).

    modules: kernel module names (``"downsample"``, ...) to import first; None: only those
    already imported, i.e. the kernels the caller's code paths use (each user imports its
    kernel module when it is imported itself). Loading every kernel module would pay for
    kernels nobody calls (~1 s of a short ``supportnode detect``). On a fresh install's empty
    cache, the first call compiles every kernel module in child processes on the usable
    cores first (`precompile.compile_cold`; at most the configured thread budget)."""
    global _precompile_tried
    t = time.perf_counter()
    configure()
    package = __package__ or "supportnode.kernels"
    for name in modules or ():
        importlib.import_module(f"{package}.{name}")
    with _LOCK:
        first, _precompile_tried = not _precompile_tried, True
    if first:
        from supportnode.kernels import precompile

        precompile.compile_cold(_threads)
    _run_warmers(None)
    return time.perf_counter() - t


def warm_only(modules: Iterable[str]) -> None:
    """Run the warm-ups of the named kernel modules (imported) only, not of the kernel modules
    they import: a compiling child's share (`precompile`)."""
    package = __package__ or "supportnode.kernels"
    _run_warmers({f"{package}.{name}" for name in modules})


def _run_warmers(modules: set[str] | None) -> None:
    """Run the registered warm-ups not run yet in this process (of ``modules`` only, full
    names, when given)."""
    with _LOCK:
        todo = [
            fn
            for fn in _WARMERS
            if fn not in _WARMED and (modules is None or fn.__module__ in modules)
        ]
        _WARMED.update(todo)
    for fn in todo:
        fn()
