"""Diagnostics while both threads count rejects: no "dictionary changed size during
iteration", no count lost (issue 20's race, hammered)."""

from __future__ import annotations

import threading

from supportnode.node.diagnostics import Rejects
from supportnode.node.node import Node


def test_rejects_from_two_threads_while_diagnostics_are_made():
    """Two threads (the receiving and the detecting side) add rejects under ever new reasons
    while the main thread makes Diagnostics as fast as it can: every message is made, and the
    final counts are exact."""
    node = Node()
    per_thread, errors = 3000, []
    start = threading.Barrier(3)

    def hammer(side: str) -> None:
        start.wait()
        try:
            for i in range(per_thread):
                # A new reason every few rejects: the dict of reasons keeps growing.
                node._wire.reject(f"{side}_{i // 3}", f"{side} reject {i}")
                if i % 50 == 0:
                    try:
                        raise RuntimeError("boom")
                    except RuntimeError as err:
                        node._wire.internal_error(side, err)
        except Exception as err:  # pragma: no cover - the failure being tested for
            errors.append(err)

    threads = [threading.Thread(target=hammer, args=(s,)) for s in ("recv", "detect")]
    for t in threads:
        t.start()
    start.wait()
    made = 0
    while any(t.is_alive() for t in threads):
        d = node.diagnostics()
        # One moment's copy: the reasons add up to the total.
        assert d.counters["scans_rejected"] == sum(
            v for k, v in d.counters.items() if k.startswith("rejected_")
        )
        made += 1
    for t in threads:
        t.join()
    assert not errors and made > 0
    d = node.diagnostics()
    internal = 2 * len(range(0, per_thread, 50))
    assert d.counters["scans_rejected"] == 2 * per_thread + internal
    assert d.counters["rejected_internal_error"] == internal
    assert d.counters["rejected_recv_0"] == 3 and d.counters["rejected_detect_999"] == 3


def test_rejects_counts_are_copies():
    r = Rejects()
    r.add("a", "first")
    counts = r.counts()
    r.add("b", "second")
    assert counts == {"a": 1} and r.counts() == {"a": 1, "b": 1} and r.total == 2
    assert r.take_last() == "second" and r.take_last() == ""
