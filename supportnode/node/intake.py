"""What the node admits from its scan topic, decided as each message comes off the socket.

Every reject reason is decided here, before a message takes a place in the newest-scans queue
(or the latest-job mailbox): a message the node cannot use must never push out a good scan
that waits there. A message is rejected under exactly one reason (`REASONS`, documented in
docs/protocol.md section 9): the first check it fails, in this order: decoding (the wire
protocol's own reasons), message type, the scan's content (`scan_problem`: no points, no finite
point, a pose or points beyond the map's coordinates), then its stamp against the stream's
timeline (`StampGate`). ``seq`` is looked at for every decoded scan
(`supportnode.msgs.SeqCounter`) but never rejects one: it is the sender's count, and only says how many messages were lost on the way.

Pure bookkeeping: frames in, a PointCloud or a `Reject` out; no sockets, threads or logging.
Owned by the receiving thread.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from supportnode.errors import ProtocolError
from supportnode.geometry.transform import quaternion_matrix
from supportnode.map import coordinate_range
from supportnode.msgs import Limits, PointCloud, SeqCounter, decode_any
from supportnode.params import NodeParams

__all__ = [
    "BACKWARD_S",
    "REASONS",
    "Intake",
    "Reject",
    "StampGate",
    "scan_problem",
]

#: Reject reason -> what it means (the node counts ``rejected_<reason>``).
REASONS: dict[str, str] = {
    "malformed": "not a valid message: framing, header, buffer layout, types, values",
    "version": "a schema version this node does not speak",
    "nonfinite": "a NaN/Inf in the header (stamp, pose, gravity, imu_orientation)",
    "bad_gravity": "a gravity vector without a usable direction (zero, or a magnitude "
    "outside [0.001, 1000])",
    "too_many_points": "more points than node.max_points",
    "oversized": "more bytes than node.max_message_bytes",
    "wrong_type": "a message other than a PointCloud on the scan topic",
    "empty": "a scan of 0 points",
    "all_nonfinite": "a scan whose every point has a NaN/Inf coordinate",
    "out_of_range": "a pose translation, or points through the pose, beyond the map's "
    "coordinate range (about +-105 km in x, y and +-13 km in z at 5 cm voxels)",
    "stamp_jump": "a stamp that leaves the stream's timeline (more than node.max_stamp_jump "
    "ahead, or backwards) while the old timeline goes on, or before a second scan on it",
    "unusable": "a scan the map or detection refused (should not happen once admitted)",
    "internal_error": "a bug met while handling the message (logged with its traceback)",
}
#: A stamp this much before the previous one is backwards, s (jitter of a few us is not).
BACKWARD_S = 1e-3
# A new timeline becomes the stream's when this many scans in a row follow it and the old one
# has been silent this long (receive time): a source that restarted stops its old timeline,
# a hostile or second sender among the real one does not.
_CONFIRM_SCANS = 2
_SILENCE_S = 1.0


@dataclass(frozen=True)
class Reject:
    """Why a message was not admitted: a `REASONS` key and one line of detail."""

    reason: str
    text: str


def scan_problem(cloud: PointCloud, limit: np.ndarray) -> Reject | None:
    """What makes a decoded scan unusable on its own, or None. limit: (3,) metres, the map's
    coordinate range (`supportnode.map.coordinate_range`)."""
    if cloud.count == 0:
        if cloud.dropped_nonfinite:
            text = f"all {cloud.dropped_nonfinite} points have a NaN/Inf coordinate"
            return Reject("all_nonfinite", text)
        return Reject("empty", "scan has 0 points")
    if cloud.pose is not None:
        t = cloud.pose.translation
        if np.any(np.abs(t) > limit):
            return Reject("out_of_range", f"pose translation {t.tolist()} beyond {_limit(limit)}")
    lo, hi = _extent(cloud)
    if np.any(np.maximum(np.abs(lo), np.abs(hi)) > limit):
        where = f"spans {lo.round(1).tolist()} to {hi.round(1).tolist()}"
        return Reject("out_of_range", f"points in the map frame {where}, beyond {_limit(limit)}")
    return None


def _extent(cloud: PointCloud) -> tuple[np.ndarray, np.ndarray]:
    """(3,) lower and upper corner of the scan's points in the map frame (through its pose)."""
    f = cloud.fields
    with np.errstate(over="ignore", invalid="ignore"):  # float32 fields near their maximum
        lo = np.array([float(np.min(f[k])) for k in "xyz"])
        hi = np.array([float(np.max(f[k])) for k in "xyz"])
        if cloud.pose is None:
            return lo, hi
        corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T
        c = corners @ quaternion_matrix(cloud.pose.rotation).T + cloud.pose.translation
    return c.min(axis=0), c.max(axis=0)


def _limit(limit: np.ndarray) -> str:
    return f"+-{limit[0]:.0f} m in x, y and +-{limit[2]:.0f} m in z"


class StampGate:
    """The stream's timeline: a scan more than ``max_jump`` seconds ahead of the last admitted
    one, or more than `BACKWARD_S` behind it, is rejected, unless it continues a new timeline
    that the rejected scans before it began (each within ``max_jump`` of the one before, none
    backwards) and the old timeline has gone quiet. That is how a source that really restarted
    (a driver or replay started again: its old timeline stops, every scan after is on the new
    one) is told from bad stamps among good ones (a far-future one, a burst of them, stamps
    alternating between two clocks): the first needs `_CONFIRM_SCANS` scans in a row on the
    new timeline and `_SILENCE_S` without a scan on the old one, and gets its map reset by the
    node when the new timeline lies behind; the second never gets in, as long as the real
    source keeps sending."""

    def __init__(self, max_jump: float) -> None:
        self.max_jump = float(max_jump)
        self.restarts = 0  # new timelines confirmed
        self._last: float | None = None
        self._last_at = 0.0  # receive time (monotonic) of the last admitted scan
        self._candidate: tuple[float, int] | None = None  # (last stamp, scans) of a new one

    def _follows(self, stamp: float, last: float) -> bool:
        return -BACKWARD_S <= stamp - last <= self.max_jump

    def admit(self, stamp: float, now: float) -> str | None:
        """None when ``stamp`` is admitted (the timeline moves to it), else why not.
        now: receive time, s (monotonic)."""
        if self._last is None or self._follows(stamp, self._last):
            self._last, self._last_at, self._candidate = stamp, now, None
            return None
        c = self._candidate
        scans = c[1] + 1 if c is not None and self._follows(stamp, c[0]) else 1
        if scans >= _CONFIRM_SCANS and now - self._last_at >= _SILENCE_S:
            self._last, self._last_at, self._candidate = stamp, now, None
            self.restarts += 1
            return None
        self._candidate = (stamp, scans)
        return (
            f"stamp {stamp:.6f} is {stamp - self._last:+.6g} s from the previous scan's "
            f"(node.max_stamp_jump {self.max_jump:g} s; a new timeline needs "
            f"{_CONFIRM_SCANS} scans in a row and {_SILENCE_S:g} s without the old one)"
        )


class Intake:
    """The receiving thread's checks of the scan topic (see the module docstring).

    ``admit(frames)`` -> the decoded scan, or a `Reject`. ``counters()``: the stream's counts
    for diagnostics (seq gaps and restarts, confirmed new timelines)."""

    def __init__(self, cfg: NodeParams) -> None:
        self.limits = Limits(max_points=cfg.max_points, max_message_bytes=cfg.max_message_bytes)
        self.limit = coordinate_range(cfg.map.voxel_size)
        self.seq = SeqCounter()
        self.stamps = StampGate(cfg.max_stamp_jump)

    def admit(self, frames: Any) -> PointCloud | Reject:
        try:
            msg = decode_any(frames, self.limits)
        except ProtocolError as err:
            return Reject(err.reason, str(err))
        if not isinstance(msg, PointCloud):
            return Reject("wrong_type", f"expected a PointCloud on the scan topic, got {msg.TYPE}")
        self.seq.observe(msg.seq)
        problem = scan_problem(msg, self.limit)
        if problem is not None:
            return Reject(problem.reason, f"scan seq {msg.seq}: {problem.text}")
        why = self.stamps.admit(msg.stamp, time.monotonic())
        if why is not None:
            return Reject("stamp_jump", f"scan seq {msg.seq}: {why}")
        return msg

    def counters(self) -> dict[str, int]:
        return {
            "seq_gaps": self.seq.gaps,
            "seq_restarts": self.seq.restarts,
            "stamp_restarts": self.stamps.restarts,
        }
