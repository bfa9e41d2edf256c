"""The one hand-off between the node's receiving and detecting threads: the latest job."""

from __future__ import annotations

import threading

from supportnode.node.core import Job

__all__ = ["Mailbox"]


class Mailbox:
    """Holds at most one `Job`, the newest. A job put while another waits replaces it (the
    detector was busy: the older scan is skipped, counted, and its changed region joins the
    newer one's, so the next detection covers both; the map has every scan either way)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._job: Job | None = None
        self._closed = False
        self._merging = False
        self.skipped = 0  # jobs replaced before a detection took them
        self.obstacles_skipped = 0  # jobs folded into a newer one after their surfaces

    def put(self, job: Job) -> None:
        """Leave ``job`` for the detector, replacing one it has not taken."""
        with self._cond:
            if self._job is not None:
                self.skipped += 1
                job = job.merged_with(self._job)
            self._job = job
            self._cond.notify()

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
            return None if self._closed else job

    def close(self) -> None:
        """Wake the detector for good (the node stops)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
