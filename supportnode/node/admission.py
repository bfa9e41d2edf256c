"""What comes off the wire: each message decoded and admitted or rejected, rejects counted by
reason and logged (rate-limited), from either of the node's threads."""

from __future__ import annotations

import logging
import time
from typing import Any, NamedTuple

from supportnode.msgs import PointCloud
from supportnode.node.diagnostics import Rejects
from supportnode.node.intake import Intake, Reject
from supportnode.node.latency import RateLimitedLog
from supportnode.params import NodeParams

__all__ = ["Admission", "Decoded"]


class Decoded(NamedTuple):
    """A scan decoded as it came off the socket (the subscriber's check), and how long that
    took, s."""

    cloud: PointCloud
    seconds: float


class Admission:
    """The scan stream's checks (`Intake`, receiving thread) and the node's rejects.

    `check` is the subscriber's check: a message is decoded as it comes off the socket, so
    that only usable scans take the newest-scan place (a malformed message after a scan must
    not push it out). `reject` and `internal_error` may be called from any thread.
    """

    def __init__(self, cfg: NodeParams, log: logging.Logger) -> None:
        self.name = cfg.name
        self.intake = Intake(cfg)
        self.rejects = Rejects()
        self._reject_log = RateLimitedLog(log, cfg.reject_log_period)
        # Its own limit: a flood of rejects must not hide an internal error, nor the reverse.
        self.error_log = RateLimitedLog(log, cfg.reject_log_period)

    def check(self, frames: Any) -> Decoded | None:
        """The scan in raw ``frames`` and its decoding time, or None (counted, logged)."""
        t = time.perf_counter()
        try:
            msg = self._admit(frames)
        except Exception as err:  # a decoder bug must not end the node's receiving loop
            self.internal_error("decoding", err)
            return None
        return None if msg is None else Decoded(msg, time.perf_counter() - t)

    def decoded(self, frames: Any) -> tuple[PointCloud | None, float]:
        """(scan or None, seconds it took to decode) of raw frames or a `Decoded`."""
        if isinstance(frames, Decoded):
            return frames.cloud, frames.seconds
        t = time.perf_counter()
        msg = self._admit(frames)
        return msg, time.perf_counter() - t

    def _admit(self, frames: Any) -> PointCloud | None:
        got = self.intake.admit(frames)
        if isinstance(got, Reject):
            self.reject(got.reason, got.text)
            return None
        return got

    def reject(self, reason: str, text: str, log: RateLimitedLog | None = None) -> None:
        """Count a message not used under ``reason``; log it (rate-limited)."""
        self.rejects.add(reason, text)
        if log is None:
            self._reject_log.warning(f"{self.name}: rejected a scan ({reason}): {text}")
        else:
            log.warning(f"{self.name}: internal error, {text}", exc_info=True)

    def internal_error(self, where: str, err: Exception) -> None:
        """A bug met while handling a scan: counted as an internal_error reject, logged with
        its traceback at most once per ``node.reject_log_period``. Call from an except block."""
        self.reject("internal_error", f"{where}: {type(err).__name__}: {err}", self.error_log)
