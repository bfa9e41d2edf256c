"""The cyclic garbage collector in a command's own process.

A fresh ``supportnode detect`` creates ~1.3e5 Python objects while it imports numpy, numba and
the pipeline and loads its compiled kernels; they live until the process ends. The collector
goes over them again and again as they come (~0.1 s of a 1 s detect) and the interpreter's
shutdown collects several times more (~0.2 s). Inside :func:`long_lived` the collector is off,
and when ``main`` is the process (not a caller's Python: tests, notebooks) what was made there
is frozen (``gc.freeze``): later collections, shutdown's included, leave it out.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

_state = {"entry": False}


def process_entry() -> None:
    """Note that this process is the command's (``main`` called from the command line)."""
    _state["entry"] = True


def freeze() -> None:
    """Leave every object made so far out of later collections, in the command's process only
    (frozen garbage is never freed: harmless when the process ends soon after)."""
    if _state["entry"]:
        gc.freeze()


@contextmanager
def long_lived() -> Iterator[None]:
    """Imports and kernel loads inside: no collection meanwhile, frozen afterwards."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        freeze()
        if enabled:
            gc.enable()
