"""The scan stream's bookkeeping: seq gaps bounded, stamp jumps told from restarts."""

from __future__ import annotations

import pytest

from supportnode.msgs import MAX_SEQ_GAP, SeqCounter
from supportnode.node.intake import StampGate


@pytest.mark.parametrize(
    ("seqs", "gaps", "restarts"),
    [
        ([1, 2, 3], 0, 0),
        ([1, 5], 3, 0),
        ([1, 2**64 - 1, 3], 0, 2),
        ([2**63, 2**63 + 5], 4, 0),
        ([5, 5], 0, 1),  # a repeat
        ([0, MAX_SEQ_GAP + 1], MAX_SEQ_GAP, 0),
        ([0, MAX_SEQ_GAP + 2], 0, 1),
        ([2**64 - 1, 0], 0, 1),  # a wrap
    ],
)
def test_seq_gaps_are_bounded(seqs, gaps, restarts):
    c = SeqCounter()
    for s in seqs:
        c.observe(s)
    assert (c.gaps, c.restarts) == (gaps, restarts)


def test_endless_hostile_seqs_stay_in_int64():
    c = SeqCounter()
    for i in range(10_000):
        c.observe(0 if i % 2 else 2**64 - 1)
        c.observe(MAX_SEQ_GAP * i)
    assert 0 <= c.gaps < 2**63 and c.restarts <= 20_000


def test_stamp_gate():
    g = StampGate(max_jump=30.0)
    assert g.admit(100.0, 0.0) is None
    assert g.admit(100.1, 0.1) is None
    assert "node.max_stamp_jump 30" in g.admit(1e9, 0.2)  # far future
    assert g.admit(1e9 + 0.1, 0.25) is not None  # a second one: the real source goes on
    assert g.admit(100.2, 0.3) is None
    assert g.admit(100.2 - 0.0005, 0.4) is None  # jitter below BACKWARD_S
    assert g.admit(99.0, 0.5) is not None  # backwards
    assert g.admit(131.0, 0.6) is not None  # beyond the bound ahead
    assert g.admit(129.0, 0.7) is None  # within it
    # a restart: the old timeline stops, the new one goes on
    assert g.admit(5.0, 2.0) is not None
    assert g.admit(5.1, 2.1) is None and g.restarts == 1
    assert g.admit(5.2, 2.2) is None
