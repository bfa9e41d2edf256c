"""Cached kernels loaded without numba's compile-time set-up: a one-shot process's start-up.

Three costs of numba's that a process only loading its kernels from the cache does not need
(measured on a fresh ``supportnode detect`` of the 150k shelf, ~60 kernel loads, 2-core host):

- **The registries.** Each cache load first refreshes the target context: its first call
  imports and registers every typing and lowering registry numba has (``numba.np.*``,
  ``numba.typed.*``, ``numba.cpython.*``, scipy.linalg through ``numba.np.linalg``), ~0.1 s.
  Only compiling uses them, and a compile refreshes the context itself
  (``numba.core.compiler.CompilerBase``); a load needs the runtime (NRT) initialised, no more.
- **The linking bitcode.** Each cached library holds its machine code and its LLVM bitcode;
  numba parses the bitcode on every load (~1.3 ms) and lists its symbols (~0.5 ms), for a
  later compile that links the library into another. Here it is parsed when one does; a
  loaded library's functions are looked up in the JIT engine directly (0 when absent, as
  numba's own look-up answers).
- **The LLVM lock events.** numba hooks every llvmlite call to fire two events that feed its
  compile timers ("numba:llvm_lock"); loading the kernels makes ~12,000 such calls (~25 ms).

:func:`load_lightly` turns all three off in the calling process. It is for supportnode's own
processes (``supportnode detect``, the node), like `runtime.keep_freed_memory`: a planner that
imports supportnode keeps numba as it is. Each change checks that numba's code is the shape
it knows and leaves it alone otherwise (then the process only starts slower).
"""

from __future__ import annotations

import threading
from typing import Any

_LOCK = threading.Lock()
_applied: bool | None = None  # None: not tried in this process
# The names numba's functions refer to when they are the versions replaced or wrapped here.
_LOAD_OVERLOAD_NAMES = {"refresh", "_guard_against_spurious_io_errors", "_load_overload"}
_UNSERIALIZE_NAMES = {
    "ValueError", "_codegen", "_engine", "_final_module", "_finalize_final_module",
    "_load_defined_symbols", "_set_compiled_object", "_shared_module", "create_library",
    "enable_object_caching", "isinstance", "ll", "parse_bitcode",
}  # fmt: skip
_POINTER_NAMES = {
    "_codegen", "_engine", "_ensure_finalized", "get_function_address", "is_symbol_defined"
}  # fmt: skip
_BITCODE = "_supportnode_bitcode"  # a lightly loaded library's linking bitcode, unparsed


def load_lightly() -> bool:
    """Skip numba's registry refresh and bitcode parsing on cache loads, and its LLVM lock
    events, in this process; whether both load changes took (numba's code as known).
    Idempotent, thread-safe."""
    global _applied
    with _LOCK:
        if _applied is None:
            refresh, bitcode = _skip_refresh(), _defer_bitcode()
            _drop_lock_events()
            _applied = refresh and bitcode
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


def _defer_bitcode() -> bool:
    import llvmlite.binding as ll
    from numba.core import codegen

    library: Any = codegen.CPUCodeLibrary
    unserialize = library.__dict__["_unserialize"].__func__
    linking = library._get_module_for_linking
    pointer = codegen.JITCodeLibrary.get_pointer_to_function
    if (
        set(unserialize.__code__.co_names) != _UNSERIALIZE_NAMES
        or "_shared_module" not in linking.__code__.co_names
        or set(pointer.__code__.co_names) != _POINTER_NAMES
    ):
        return False

    def _unserialize(cls: Any, codegen_: Any, state: Any) -> Any:
        name, kind, data = state
        if kind != "object":
            return unserialize(cls, codegen_, state)
        object_code, shared_bitcode = data
        self = codegen_.create_library(name)
        self.enable_object_caching()
        self._set_compiled_object(object_code)
        setattr(self, _BITCODE, shared_bitcode)
        self._finalize_final_module()
        return self

    def _get_module_for_linking(self: Any) -> Any:
        bitcode = self.__dict__.pop(_BITCODE, None)
        if bitcode is not None and self._shared_module is None:  # what the load skipped
            self._shared_module = ll.parse_bitcode(bitcode)
            self._codegen._engine._load_defined_symbols(self._shared_module)
        return linking(self)

    def get_pointer_to_function(self: Any, name: str) -> int:
        if _BITCODE not in self.__dict__:
            return int(pointer(self, name))
        self._ensure_finalized()
        return int(self._codegen._engine.get_function_address(name))

    library._unserialize = classmethod(_unserialize)
    library._get_module_for_linking = _get_module_for_linking
    codegen.JITCodeLibrary.get_pointer_to_function = get_pointer_to_function  # type: ignore[method-assign]
    return True


def _drop_lock_events() -> None:
    import llvmlite.binding.ffi as ffi
    import numba.core.base  # noqa: F401  (registers the callbacks on import)

    lock: Any = getattr(ffi.lib, "_lock", None)
    for acquire, release in list(getattr(lock, "_cblist", ())):
        if getattr(acquire, "__module__", None) == "numba.core.base":
            ffi.unregister_lock_callback(acquire, release)
