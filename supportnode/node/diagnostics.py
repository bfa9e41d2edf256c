"""The node's counters from both threads, and the Diagnostics message made of them.

Each side of the node writes its own counters (`NodeCore`'s fixed-key dicts, the intake's);
rejects come from both threads, so `Rejects` counts them under a lock, and `diagnostics`
reads copies: a reason added while diagnostics are made never breaks the iteration.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Mapping

from supportnode.msgs import Diagnostics
from supportnode.node.gravity import SOURCES, Gravity
from supportnode.node.latency import LatencyWindow

__all__ = ["Rejects", "diagnostics_message", "rss_mb"]


class Rejects:
    """Messages not used, counted by reason, and the text of the last one (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._by_reason: dict[str, int] = {}
        self._total = 0
        self.last = ""

    def add(self, reason: str, text: str) -> None:
        with self._lock:
            self._by_reason[reason] = self._by_reason.get(reason, 0) + 1
            self._total += 1
            self.last = text

    def snapshot(self) -> tuple[int, dict[str, int]]:
        """(total, reason -> count), taken at one moment: the counts sum to the total."""
        with self._lock:
            return self._total, dict(self._by_reason)

    def counts(self) -> dict[str, int]:
        """A copy: reason -> count."""
        with self._lock:
            return dict(self._by_reason)

    @property
    def total(self) -> int:
        return self._total

    def take_last(self) -> str:
        """The last reject's text, cleared (each Diagnostics reports it once)."""
        with self._lock:
            last, self.last = self.last, ""
            return last


def diagnostics_message(
    *,
    node: str,
    seq: int,
    counters: Mapping[str, int],
    rejects: Rejects,
    map_stats: Mapping[str, int],
    gravity: Gravity,
    latency: LatencyWindow,
    gauges: Mapping[str, float],
    topic: str,
    last_reject: str,
) -> Diagnostics:
    """One Diagnostics message: ``counters`` (copies of each side's), rejects by reason
    (``rejected_<reason>``), the map's counters (``map_<name>``), gravity and memory gauges,
    the latency window; level warn before the first scan and after a reject."""
    out = dict(counters)
    out["scans_rejected"], by_reason = rejects.snapshot()
    out.update({f"rejected_{k}": v for k, v in by_reason.items()})
    out.update({f"map_{k}": int(v) for k, v in map_stats.items()})
    up = gravity.up
    g = {
        "map_voxels": float(map_stats.get("voxels", 0)),
        "gravity_tilt_deg": gravity.tilt_deg,
        "gravity_up_x": float(up[0]),
        "gravity_up_y": float(up[1]),
        "gravity_up_z": float(up[2]),
        "gravity_source": float(SOURCES.index(gravity.source)),
        "rss_mb": rss_mb(),
        **gauges,
    }
    level, message = "ok", ""
    if out.get("scans_processed", 0) == 0:
        level, message = "warn", f"no scans processed yet on topic {topic}"
    if last_reject:
        level, message = "warn", f"last reject: {last_reject}"[:500]
    return Diagnostics(
        stamp=time.time(),
        node=node,
        level=level,
        message=message,
        counters=out,
        latencies=latency.stats(),
        gauges={k: v for k, v in g.items() if math.isfinite(v)},
        seq=seq,
    )


def rss_mb() -> float:
    """Resident memory of this process in MiB (Linux /proc; peak RSS elsewhere)."""
    try:
        with open(f"/proc/{os.getpid()}/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
