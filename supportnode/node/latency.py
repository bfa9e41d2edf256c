"""Bookkeeping for the node's diagnostics: latency windows, counters and rate-limited logging.

Pure Python and numpy, no sockets: the loop in `supportnode.node.node` owns the clock.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable

import numpy as np

from supportnode.msgs import LatencyStats

__all__ = ["LatencyWindow", "RateLimitedLog"]


class LatencyWindow:
    """The last ``size`` samples (seconds) of each named stage, and their p50 / p99.

    A fixed window rather than all-time statistics: diagnostics should say how the node is doing
    now, and memory must stay flat on an endless run.
    """

    def __init__(self, size: int = 1000) -> None:
        self.size = int(size)
        self._samples: dict[str, collections.deque[float]] = {}
        # The pipelined node adds from two threads while diagnostics read.
        self._lock = threading.Lock()

    def add(self, stage: str, seconds: float) -> None:
        """Record one sample of ``stage``."""
        with self._lock:
            q = self._samples.get(stage)
            if q is None:
                q = self._samples[stage] = collections.deque(maxlen=self.size)
            q.append(max(0.0, float(seconds)))

    def add_all(self, timings: dict[str, float]) -> None:
        """Record one sample of every stage in ``timings`` (stage -> seconds)."""
        for stage, seconds in timings.items():
            self.add(stage, seconds)

    def samples(self, stage: str) -> np.ndarray:
        """(K,) float64 seconds of ``stage`` in the window (empty when never recorded)."""
        with self._lock:
            return np.asarray(self._samples.get(stage, ()), dtype=np.float64)

    def stats(self) -> dict[str, LatencyStats]:
        """p50 and p99 of every stage with at least one sample."""
        out = {}
        with self._lock:
            window = {stage: np.asarray(q) for stage, q in self._samples.items() if q}
        for stage, q in window.items():
            p50, p99 = np.percentile(q, [50, 99])
            out[stage] = LatencyStats(p50=float(p50), p99=float(p99))
        return out


class RateLimitedLog:
    """At most one log line per ``period`` seconds; lines held back are counted and the count
    goes into the next line, so a flood of bad messages neither fills the log nor hides."""

    def __init__(
        self,
        logger: logging.Logger,
        period: float,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.logger = logger
        self.period = float(period)
        self.clock = clock
        self._last: float | None = None
        self._suppressed = 0

    def warning(self, text: str, exc_info: bool = False) -> bool:
        """Log ``text`` unless a line went out less than ``period`` ago; True when logged.
        exc_info: with the traceback of the exception being handled (internal errors)."""
        now = self.clock()
        if self._last is not None and now - self._last < self.period:
            self._suppressed += 1
            return False
        more = f" ({self._suppressed} more since the last report)" if self._suppressed else ""
        self.logger.warning("%s%s", text, more, exc_info=exc_info)
        self._last = now
        self._suppressed = 0
        return True
