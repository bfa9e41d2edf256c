"""The cyclic garbage collector, and the interpreter's shutdown, in a command's own process.

A fresh ``supportnode detect`` creates ~1.3e5 Python objects while it imports numpy, numba and
the pipeline and loads its compiled kernels; they live until the process ends. The collector
goes over them again and again as they come (~0.1 s of a 1 s detect) and the interpreter's
shutdown collects several times more (~0.2 s). Inside :func:`long_lived` the collector is off,
and when ``main`` is the process (not a caller's Python: tests, notebooks) what was made there
is frozen (``gc.freeze``): later collections, shutdown's included, leave it out.

The shutdown still frees those objects one by one, ~30 ms after a detect: a command that
leaves nothing to finish (its files closed, no thread, no viewer to flush) says so with
:func:`nothing_left`, and its process then ends at once when ``main`` returns (:func:`end`).
"""

from __future__ import annotations

import gc
import logging
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

_state = {"entry": False, "nothing_left": False}


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


def nothing_left() -> None:
    """The command's outputs are written and closed and it started no thread or child that
    must finish: its process may end without the interpreter's shutdown."""
    _state["nothing_left"] = True


def end(code: int) -> None:
    """End the command's process now with ``code`` when :func:`nothing_left` was said (stdout,
    stderr and logging flushed first); otherwise return, for the usual shutdown."""
    if not (_state["entry"] and _state["nothing_left"]):
        return
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: as the shutdown would
            pass
    logging.shutdown()
    os._exit(code)
