"""Messages lost on the way, from a sender's ``seq`` (any uint64 on the wire)."""

from __future__ import annotations

__all__ = ["MAX_SEQ_GAP", "SeqCounter"]

#: A seq jump larger than this is a restart or a wrap of the sender's counter, not lost messages.
MAX_SEQ_GAP = 1_000_000


class SeqCounter:
    """Missed messages from the sender's ``seq``: a step of k > 1 means k - 1 lost on the way.
    A jump beyond `MAX_SEQ_GAP`, or back (including a repeat), is a restart or a wrap of the
    sender's counter (any uint64 is a valid seq): counted as such, not as lost messages. Both
    counts grow by at most MAX_SEQ_GAP a message, so they stay far inside int64."""

    def __init__(self) -> None:
        self.gaps = 0
        self.restarts = 0
        self._last: int | None = None

    def observe(self, seq: int) -> None:
        last, self._last = self._last, int(seq)
        if last is None:
            return
        step = int(seq) - last
        if 1 < step <= MAX_SEQ_GAP + 1:
            self.gaps += step - 1
        elif step > MAX_SEQ_GAP + 1 or step <= 0:
            self.restarts += 1
