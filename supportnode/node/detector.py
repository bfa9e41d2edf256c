"""The node's detecting side: takes the latest job, detects, publishes; keeps pace.

Surfaces go out as soon as they are known, then the obstacles of the same scan. When the
detector falls behind the sensor (a newer scan waits in the mailbox, or is being merged, once
a scan's surfaces are out), the newer scan's surfaces come first: the older scan's obstacles
are skipped (``obstacles_skipped``) and its region joins the newer job's, as for a replaced
job. Never twice in a row, so obstacles lag the surfaces by one scan at most (docs/node.md)."""

from __future__ import annotations

import threading
import time

from supportnode.kernels import runtime
from supportnode.node.admission import Admission
from supportnode.node.core import Job, NodeCore
from supportnode.node.latency import LatencyWindow
from supportnode.node.mailbox import Mailbox
from supportnode.node.outbox import Outbox

__all__ = ["Detector"]


class Detector:
    """The detecting thread's loop and state. wait: how long one wait for a job, or for a
    merge under way, lasts (s)."""

    def __init__(
        self,
        core: NodeCore,
        mailbox: Mailbox,
        outbox: Outbox,
        latency: LatencyWindow,
        wire: Admission,
        wait: float,
    ) -> None:
        self.core, self.mailbox, self.outbox = core, mailbox, outbox
        self.latency, self.wire, self.wait = latency, wire, wait
        self.yielded = False  # the last job's obstacles were skipped for a newer job

    def run(self, stop: threading.Event) -> None:
        """Detect the latest job, again and again, until ``stop`` is set."""
        runtime.apply_threads()  # node.threads: numba's count is set per thread
        while not stop.is_set():
            job = self.mailbox.take(self.wait)
            if job is not None:
                self.detect_and_publish(job)

    def detect_and_publish(self, job: Job) -> None:
        """Surfaces out, then the obstacles of the same seq unless they yield (see module)."""
        t = time.perf_counter()
        try:
            part = self.core.detect_surfaces(job)
            self.outbox.surfaces(part.out, job.t_recv)
            self.mailbox.surfaces_sent()  # the receiving side's clearing waited for them
            self.yielded = not self.yielded and self.mailbox.yield_to_newer(job, self.wait)
            if self.yielded:
                self.latency.add_all(part.out.timings)
                return
            out = self.core.detect_objects(part)
        except Exception as err:
            self.mailbox.surfaces_sent()  # none will come: the clearing need not wait
            self.wire.internal_error(f"detection of the scan at {job.stamp:.3f}", err)
            return
        out.timings["detect"] = time.perf_counter() - t
        try:
            self.outbox.obstacles(out, job.t_recv)
        except Exception as err:
            self.wire.internal_error(f"publishing the scan at {job.stamp:.3f}", err)
        out.timings["total"] = time.perf_counter() - job.t_recv  # receive to results, in node
        self.latency.add_all(out.timings)
