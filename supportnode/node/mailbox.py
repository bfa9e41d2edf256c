"""The one hand-off between the node's receiving and detecting threads: the latest job."""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable

from supportnode.node.core import Job

__all__ = ["Doorbell", "Mailbox"]


class Doorbell:
    """Wakes the receiving thread from its wait on the scan socket: a connected socket pair
    (a ZeroMQ poll takes its descriptor beside the subscriber's socket)."""

    def __init__(self) -> None:
        self._r, self._w = socket.socketpair()
        for end in (self._r, self._w):
            end.setblocking(False)

    def fileno(self) -> int:
        """The descriptor that turns readable when rung."""
        return self._r.fileno()

    def ring(self) -> None:
        """Wake the waiting side (a full buffer is already ringing)."""
        try:
            self._w.send(b"\0")
        except (BlockingIOError, OSError):
            pass

    def clear(self) -> None:
        """Take back every ring so far."""
        try:
            while self._r.recv(4096):
                pass
        except (BlockingIOError, OSError):
            pass

    def close(self) -> None:
        self._r.close()
        self._w.close()


class Mailbox:
    """Holds at most one `Job`, the newest. A job put while another waits replaces it (the
    detector was busy: the older scan is skipped, counted, and its changed region joins the
    newer one's, so the next detection covers both; the map has every scan either way).

    Jobs are numbered as they are put; the detector reports when the surfaces of the job it
    took are out (`surfaces_sent`, which calls ``on_sent``), and the receiving side asks
    whether those of a job it put are, or of a newer one (`surfaces_out`): its clearing waits
    for them."""

    def __init__(self, on_sent: Callable[[], None] | None = None) -> None:
        self._on_sent = on_sent
        self._cond = threading.Condition()
        self._job: Job | None = None
        self._closed = False
        self._merging = False
        self._put = 0  # jobs put so far: the number of the latest
        self._taken = 0  # the number of the job the detector took last
        self._sent = 0  # the number of the last job whose surfaces are out
        self.skipped = 0  # jobs replaced before a detection took them
        self.obstacles_skipped = 0  # jobs folded into a newer one after their surfaces

    def put(self, job: Job) -> int:
        """Leave ``job`` for the detector, replacing one it has not taken; its number."""
        with self._cond:
            if self._job is not None:
                self.skipped += 1
                job = job.merged_with(self._job)
            self._job = job
            self._put += 1
            self._cond.notify()
            return self._put

    def surfaces_sent(self) -> None:
        """The detector has sent the surfaces of the job it took last (``on_sent`` is
        called: the receiving side may be waiting for them)."""
        with self._cond:
            self._sent = self._taken
        if self._on_sent is not None:
            self._on_sent()

    def surfaces_out(self, number: int) -> bool:
        """Whether the surfaces of job ``number``, or of a newer one, are out (or the
        mailbox is closed)."""
        with self._cond:
            return self._sent >= number or self._closed

    def merging(self, busy: bool) -> None:
        """The receiving thread is merging a scan (True), or is done with it (False)."""
        with self._cond:
            self._merging = busy
            self._cond.notify_all()

    def yield_to_newer(self, job: Job, timeout: float) -> bool:
        """Whether a newer job waits, or comes from the merge under way (waited for up to
        ``timeout`` s). If one does, ``job`` (taken, its surfaces published, its objects not
        detected) is folded into it as a replaced job would be: the next detection covers
        both regions."""
        with self._cond:
            self._cond.wait_for(
                lambda: self._job is not None or not self._merging or self._closed, timeout
            )
            if self._job is None or self._closed:
                return False
            self._job = self._job.merged_with(job)
            self.obstacles_skipped += 1
            return True

    def take(self, timeout: float) -> Job | None:
        """The waiting job (removed), waiting up to ``timeout`` s; None if none came or the
        mailbox is closed."""
        with self._cond:
            if self._job is None and not self._closed:
                self._cond.wait(timeout)
            job, self._job = self._job, None
            if job is not None:
                self._taken = self._put
            return None if self._closed else job

    def close(self) -> None:
        """Wake the detector for good (the node stops)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
