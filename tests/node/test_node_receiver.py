"""The receiving side (`Receiver`) without geometry or sockets: a scan's clearing waits for
its job's surfaces, and never holds up a scan or a job."""

from __future__ import annotations

import logging
import select
import threading
import time
from collections import deque

import numpy as np
import pytest

from supportnode.msgs import PointCloud
from supportnode.node import receiver as receiving
from supportnode.node.admission import Admission
from supportnode.node.job import Job
from supportnode.node.latency import LatencyWindow
from supportnode.node.mailbox import Doorbell, Mailbox
from supportnode.node.receiver import Receiver
from supportnode.params import NodeParams


class _Sub:
    """The subscriber's `recv`: queued messages first, else a wait on ``wake``."""

    oversized = 0
    last_oversized = None

    def __init__(self) -> None:
        self.queue: deque = deque()
        self.waits = 0

    def recv(self, timeout: float, wake: int | None = None):
        self.waits += 1
        if self.queue:
            return self.queue.popleft()
        select.select([] if wake is None else [wake], [], [], min(timeout, 0.01))
        return None


class _Core:
    """Records the order of ingests and clearings; a job for every scan when ``due``."""

    def __init__(self, due: bool = True) -> None:
        self.due, self.calls = due, []

    def ingest(self, cloud: PointCloud) -> Job | None:
        self.calls.append(("ingest", cloud.seq, time.monotonic()))
        if not self.due:
            return None
        region = (np.zeros(2), np.ones(2))
        return Job(np.zeros((0, 3)), np.eye(3), 1.0, cloud.stamp, "map", 1, (1, 0), region)

    def settle(self) -> float:
        self.calls.append(("settle", None, time.monotonic()))
        return 0.0

    def settled(self) -> list[float]:
        return [t for what, _, t in self.calls if what == "settle"]


def _scan(seq: int) -> list:
    pts = np.random.default_rng(seq).uniform(-1, 1, (50, 3)).astype(np.float32)
    return PointCloud.from_xyz(pts, float(seq), "lidar", seq).encode("scan")


@pytest.fixture
def side():
    """A running Receiver, its stub core and subscriber, the mailbox; stopped after."""
    made = []

    def start(due: bool = True):
        cfg = NodeParams()
        core, sub, bell = _Core(due), _Sub(), Doorbell()
        box = Mailbox(on_sent=bell.ring)
        wire = Admission(cfg, logging.getLogger("test.receiver"))
        rec = Receiver(core, sub, wire, box, bell, LatencyWindow(), cfg)  # type: ignore[arg-type]
        stop = threading.Event()
        th = threading.Thread(target=rec.run, args=(stop, None, lambda now: now + 1.0))
        th.start()
        made.append((stop, th, bell))
        return core, sub, box

    yield start
    for stop, th, bell in made:
        stop.set()
        th.join(5)
        bell.close()


def _until(cond, timeout: float = 2.0) -> bool:
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        time.sleep(0.005)
    return cond()


def test_clearing_waits_for_the_jobs_surfaces(side):
    core, sub, box = side()
    sub.queue.append(_scan(1))
    assert box.take(2.0) is not None  # the detector takes the job
    time.sleep(0.08)
    assert core.settled() == []  # surfaces not out: no clearing yet
    t = time.monotonic()
    box.surfaces_sent()
    assert _until(lambda: len(core.settled()) == 1)
    assert core.settled()[0] - t < 0.05  # woken by the bell, not by a poll


def test_a_ring_for_an_older_job_does_not_make_the_wait_spin(side):
    core, sub, box = side()
    box.surfaces_sent()  # rung before this scan's job exists
    sub.queue.append(_scan(1))
    assert _until(lambda: any(c[0] == "ingest" for c in core.calls))
    waits = sub.waits
    time.sleep(0.1)
    assert sub.waits - waits < 30  # ~10 ms waits, not a loop
    assert core.settled() == []


def test_clearing_runs_after_a_while_without_surfaces(side, monkeypatch):
    monkeypatch.setattr(receiving, "SETTLE_WAIT_S", 0.1)
    core, sub, _ = side()
    t = time.monotonic()
    sub.queue.append(_scan(1))
    assert _until(lambda: len(core.settled()) == 1)
    assert core.settled()[0] - t >= 0.1


def test_a_scan_without_a_detection_is_cleared_at_once(side):
    core, sub, _ = side(due=False)
    sub.queue.append(_scan(1))
    assert _until(lambda: len(core.settled()) == 1)
    ingested = [t for what, _, t in core.calls if what == "ingest"]
    assert core.settled()[0] - ingested[0] < 0.05


def test_a_new_scan_is_not_held_up_by_a_clearing_that_waits(side):
    """The next scan is ingested while the previous one's surfaces are not out (the core's
    ingest then clears the previous scan itself); a job replaced in the mailbox counts as
    out once a newer job's surfaces are."""
    core, sub, box = side()
    sub.queue.append(_scan(1))
    assert _until(lambda: any(c[0] == "ingest" for c in core.calls))
    sub.queue.append(_scan(2))
    assert _until(lambda: sum(c[0] == "ingest" for c in core.calls) == 2, 0.15)
    assert core.settled() == []
    job = box.take(0.0)
    assert job is not None and job.stamp == 2.0 and box.skipped == 1
    box.surfaces_sent()
    assert _until(lambda: len(core.settled()) == 1)


def test_mailbox_numbers_jobs_and_reports_surfaces_out():
    rang = []
    box = Mailbox(on_sent=lambda: rang.append(1))
    assert box.put(_Core().ingest(PointCloud.decode(_scan(1)))) == 1
    assert not box.surfaces_out(1)
    assert box.take(0.0) is not None
    assert not box.surfaces_out(1)  # taken, not yet sent
    box.surfaces_sent()
    assert box.surfaces_out(1) and rang == [1]
    assert box.put(_Core().ingest(PointCloud.decode(_scan(2)))) == 2
    assert not box.surfaces_out(2)
    box.close()
    assert box.surfaces_out(2)  # closed: nobody will send them
