"""Cached kernels loaded without numba's compile-time set-up: a one-shot process's start-up.

Two costs of numba's that a process only loading its kernels from the cache does not need
(measured on a fresh ``supportnode detect`` of the 150k shelf, ~30 kernels, 2-core host):

- **The registries.** Each cache load first refreshes the target context: its first call
  imports and registers every typing and lowering registry numba has (``numba.np.*``,
  ``numba.typed.*``, ``numba.cpython.*``, scipy.linalg through ``numba.np.linalg``), ~0.1 s.
  Only compiling uses them, and a compile refreshes the context itself
  (``numba.core.compiler.CompilerBase``); a load needs the runtime (NRT) initialised, no more.
- **The LLVM lock events.** numba hooks every llvmlite call to fire two events that feed its
  compile timers ("numba:llvm_lock"); loading ~30 kernels makes ~12,000 such calls (~25 ms).

:func:`load_lightly` turns both off in the calling process. It is for supportnode's own
processes (``supportnode detect``, the node), like `runtime.keep_freed_memory`: a planner that
imports supportnode keeps numba as it is. It checks numba's code is the shape it knows and
does nothing otherwise (then the process only starts slower).
"""

from __future__ import annotations

import threading
from typing import Any

_LOCK = threading.Lock()
_applied: bool | None = None  # None: not tried in this process
# What numba's Cache.load_overload refers to when it is the refresh-then-load we replace.
_LOAD_OVERLOAD_NAMES = {"refresh", "_guard_against_spurious_io_errors", "_load_overload"}


def load_lightly() -> bool:
    """Skip numba's registry refresh on cache loads and its LLVM lock events in this process;
    whether the refresh is skipped (numba's code as known). Idempotent, thread-safe."""
    global _applied
    with _LOCK:
        if _applied is None:
            _applied = _skip_refresh()
            _drop_lock_events()
        return _applied


def _skip_refresh() -> bool:
    from numba.core import caching
    from numba.core.runtime import rtsys

    original: Any = caching.Cache.load_overload
    if set(original.__code__.co_names) != _LOAD_OVERLOAD_NAMES:
        return False  # another numba: keep its own

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:
        rtsys.initialize(target_context)  # what running the loaded code needs
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)

    load_overload.__doc__ = original.__doc__
    caching.Cache.load_overload = load_overload  # type: ignore[method-assign]
    return True


def _drop_lock_events() -> None:
    import llvmlite.binding.ffi as ffi
    import numba.core.base  # noqa: F401  (registers the callbacks on import)

    lock: Any = getattr(ffi.lib, "_lock", None)
    for acquire, release in list(getattr(lock, "_cblist", ())):
        if getattr(acquire, "__module__", None) == "numba.core.base":
            ffi.unregister_lock_callback(acquire, release)
