"""Detection in a process of its own, beside the node's receiving process.

A pipelined node merges each scan into its map in one thread while it detects on the previous
map state in another. In one process the two take turns at one interpreter lock, and a
detection's many short numpy calls queue behind the merge's: on 131,072-point scans at 10 Hz
on 2 cores the end-to-end p99 was 219-232 ms with detection in a thread and 160-164 ms with it
here (p50 about the same, 121-138 ms; both share the cores' caches and memory bandwidth either
way). A crash in native code (Qhull, an out-of-memory kill) now takes the worker, not the node.
The process boundary costs ~4.5 ms a detection: the map's points to the worker (3.5 MB) and
the result back (~170 kB, pickled).

The parent starts the worker with `DetectionWorker.start` (it does not wait for the worker's
imports: `ready` says when it can take detections) and calls `DetectionWorker.detect` from one
thread at a time. The worker keeps its own `Memo` of per-cluster results between detections,
the same answer as a detection without it. It ends when the parent closes the connection or
dies (end of file on its socket), and ignores SIGINT and SIGTERM: a Ctrl-C, or `launch`
stopping the node, signals the whole process group, and the parent decides when the worker
stops (a worker dying first would look like a crash to the node). A parent that closes the
connection while the worker detects (a normal shutdown) ends the worker quietly when it next
writes; errors in a detection are logged at most once per ``node.reject_log_period``.

Wire: a socket pair wrapped in `multiprocessing.connection.Connection` (framed messages).
Parent to worker: `DetectParams`, then per detection a header (shape, dtype, surfaces first,
free below) and the raw point bytes. Worker to parent: ``("ready", pid)`` once, then per detection
``("surfaces", items)`` when asked for surfaces first (Items with the surfaces and their free
space only), then ``("ok", items, seconds)`` or ``("error", text)``.
"""

from __future__ import annotations

import os
import pickle
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection

import numpy as np

from supportnode.node.incremental import Items
from supportnode.params import DetectParams

__all__ = ["DetectionWorker", "WorkerError", "main"]

# How often a wait for the worker looks at the stop event and at the worker's liveness.
_POLL_S = 0.05
# Time the worker gets to end by itself on close before it is killed.
_CLOSE_WAIT_S = 1.0


class WorkerError(RuntimeError):
    """The worker cannot take detections (not started, died, stopped while waiting)."""


class DetectionWorker:
    """A detection process (see the module docstring). Not thread-safe: one caller."""

    def __init__(self, proc: subprocess.Popen, conn: Connection) -> None:
        self._proc = proc
        self._conn: Connection | None = conn
        self._ready = False

    @classmethod
    def start(cls, params: DetectParams) -> DetectionWorker:
        """Launch ``python -m supportnode.node.worker`` with ``params``; returns at once."""
        parent, child = socket.socketpair()
        try:
            proc = subprocess.Popen(
                [sys.executable, "-m", "supportnode.node.worker", str(child.fileno())],
                pass_fds=(child.fileno(),),
                stdin=subprocess.DEVNULL,
            )
        except OSError as err:
            parent.close()
            raise WorkerError(f"cannot start the detection worker: {err}") from err
        finally:
            child.close()
        conn = Connection(parent.detach())
        conn.send(params)
        return cls(proc, conn)

    @property
    def pid(self) -> int:
        return self._proc.pid

    def ready(self) -> bool:
        """True once the worker has imported everything and can take a detection."""
        if self._ready or self._conn is None:
            return self._ready
        try:
            if self._conn.poll(0):
                msg = self._conn.recv()
                self._ready = isinstance(msg, tuple) and msg[:1] == ("ready",)
                if not self._ready:
                    raise WorkerError(f"detection worker sent {msg!r} instead of ready")
        except (EOFError, OSError) as err:
            self.close()
            raise WorkerError(f"detection worker ended while starting ({self._exit()})") from err
        return self._ready

    def detect(
        self,
        points: np.ndarray,
        stop: threading.Event | None = None,
        on_surfaces: Callable[[Items], None] | None = None,
        on_sent: Callable[[], None] | None = None,
        free_below: float | None = None,
    ) -> Items:
        """`incremental.full` of (N, 3) points in the worker (on_surfaces and free_below as
        there, on_surfaces called in this thread); raises WorkerError when the worker is gone or ``stop`` is set while
        waiting, RuntimeError for an error in the detection itself (the worker goes on).
        on_sent: called in this thread once the points are sent, while the worker detects
        (the caller's own work beside the detection; ``points`` may change from then on);
        not called when sending fails. An error it raises is raised once the worker's reply
        has been read."""
        if not self.ready() or self._conn is None:
            raise WorkerError("detection worker not ready")
        pts = np.ascontiguousarray(points)
        t0 = time.perf_counter()
        try:
            self._conn.send((pts.shape, pts.dtype.str, on_surfaces is not None, free_below))
            self._conn.send_bytes(pts)
            if on_sent is not None:
                try:
                    on_sent()
                except BaseException:
                    # The reply is on its way: read it, or the next detection takes it.
                    if self._reply(stop)[0] == "surfaces":
                        self._reply(stop)
                    raise
            reply = self._reply(stop)
            if reply[0] == "surfaces":
                assert on_surfaces is not None
                try:
                    on_surfaces(reply[1])
                except BaseException:
                    # The final reply is on its way: read it, or the next detection takes it.
                    self._reply(stop)
                    raise
                reply = self._reply(stop)
        except (EOFError, OSError, pickle.UnpicklingError) as err:
            self.close()
            raise WorkerError(f"detection worker died ({self._exit()})") from err
        if reply[0] == "error":
            raise RuntimeError(f"in the detection worker: {reply[1]}")
        items: Items = reply[1]
        t2 = time.perf_counter()
        items.timings["worker"] = float(reply[2])
        # The cost of the process boundary: the round trip less the detection in the worker.
        items.timings["worker_io"] = t2 - t0 - float(reply[2])
        return items

    def _reply(self, stop: threading.Event | None) -> tuple:
        assert self._conn is not None
        while not self._conn.poll(_POLL_S):
            if stop is not None and stop.is_set():
                self.close()
                raise WorkerError("stopped while the worker was detecting")
            if self._proc.poll() is not None:
                raise EOFError
        return self._conn.recv()

    def rss_mb(self) -> float:
        """Resident memory of the worker in MiB (Linux /proc); NaN when unknown."""
        try:
            with open(f"/proc/{self._proc.pid}/statm") as fh:
                return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
        except (OSError, ValueError, IndexError):
            return float("nan")

    def _exit(self) -> str:
        code = self._proc.poll()
        return "still running" if code is None else f"exit code {code}"

    def close(self) -> None:
        """End the worker (idempotent): end of file on its socket, then a kill after
        _CLOSE_WAIT_S if it is still busy."""
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        try:
            self._proc.wait(_CLOSE_WAIT_S)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()


# The parent closed the connection: a shutdown, not an error.
_PARENT_GONE = (BrokenPipeError, ConnectionResetError, EOFError)


def _serve(conn: Connection) -> int:
    # Imported here: the parent imports this module without paying for the pipeline.
    import logging

    from supportnode.geometry.memo import Memo
    from supportnode.node import incremental
    from supportnode.node.allocator import retain_freed_memory
    from supportnode.node.latency import RateLimitedLog

    retain_freed_memory()  # as the node's own process: the working set repeats every scan
    params = conn.recv()
    logger = logging.getLogger("supportnode.worker")
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("[detection worker] %(levelname)s %(message)s"))
        logger.addHandler(handler)
        logger.propagate = False
    errors = RateLimitedLog(logger, params.node.reject_log_period)
    memo = Memo()
    conn.send(("ready", os.getpid()))
    while True:
        try:
            shape, dtype, surfaces_first, free_below = conn.recv()
            points = np.empty(shape, np.dtype(dtype))
            conn.recv_bytes_into(points.reshape(-1))  # 1-D: the buffer's length is its size
        except (EOFError, OSError):
            return 0  # the parent closed the connection or died
        t = time.perf_counter()
        try:
            early = (lambda part: conn.send(("surfaces", part))) if surfaces_first else None
            items = incremental.full(
                points, params, memo=memo, on_surfaces=early, free_below=free_below
            )
            conn.send(("ok", items, time.perf_counter() - t))
        except _PARENT_GONE:
            return 0
        except Exception as err:  # reported to the parent, which logs and counts it
            errors.warning(f"detection failed: {traceback.format_exc()}")
            memo = Memo()  # a detection that failed half way may have left it partial
            try:
                conn.send(("error", f"{type(err).__name__}: {err}"))
            except _PARENT_GONE:
                return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the worker process: ``python -m supportnode.node.worker FD``."""
    args = sys.argv[1:] if argv is None else argv
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    try:
        fd = int(args[0])
    except (IndexError, ValueError):
        print("usage: python -m supportnode.node.worker FD (started by the node)", file=sys.stderr)
        return 2
    return _serve(Connection(fd))


if __name__ == "__main__":
    sys.exit(main())
