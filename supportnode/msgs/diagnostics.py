"""``Diagnostics``: a node's health as one msgpack map (no buffers)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from supportnode.msgs._wire import (
    Check,
    Decodable,
    Header,
    Limits,
    encode_frames,
    expect_type,
    short,
)

__all__ = ["LEVELS", "Diagnostics", "LatencyStats"]

#: Status levels, least to most severe.
LEVELS = ("ok", "warn", "error")


@dataclass(frozen=True)
class LatencyStats:
    """Latency percentiles of one processing stage, seconds."""

    p50: float
    p99: float


@dataclass(eq=False)
class Diagnostics(Decodable):
    """Counters (int64), latencies per stage (seconds), gauges (finite float64) and a status.

    Every float is finite on the wire; send a counter or leave a gauge out rather than NaN.
    """

    TYPE: ClassVar[str] = "Diagnostics"

    stamp: float  # seconds
    node: str
    level: str = "ok"  # one of LEVELS
    message: str = ""
    counters: dict[str, int] = field(default_factory=dict)
    latencies: dict[str, LatencyStats] = field(default_factory=dict)
    gauges: dict[str, float] = field(default_factory=dict)
    frame_id: str = ""
    seq: int = 0

    def _header_keys(self) -> dict[str, Any]:
        return {
            "node": self.node,
            "level": self.level,
            "message": self.message,
            "counters": {k: v for k, v in self.counters.items()},
            "latencies": {k: {"p50": v.p50, "p99": v.p99} for k, v in self.latencies.items()},
            "gauges": {k: v for k, v in self.gauges.items()},
        }

    def encode(self, topic: str | bytes) -> list[bytes | memoryview]:
        """``[topic, header]``; the message is checked as a receiver would check it."""
        name = topic if isinstance(topic, str) else topic.decode("utf-8", "replace")
        extra = self._header_keys()
        try:
            extra["counters"] = {k: int(v) for k, v in extra["counters"].items()}
            extra["gauges"] = {k: float(v) for k, v in extra["gauges"].items()}
            extra["latencies"] = {
                k: {q: float(x) for q, x in v.items()} for k, v in extra["latencies"].items()
            }
        except (TypeError, ValueError, OverflowError) as err:
            Check(name, "cannot encode: ").fail(f"diagnostics values are not numbers: {err}")
        _check_keys(Check(name, "cannot encode: "), extra)
        return encode_frames(topic, self.TYPE, self.stamp, self.frame_id, self.seq, [], extra)

    @classmethod
    def _from_parsed(cls, header: Header, buffers: dict[str, Any], limits: Limits) -> Diagnostics:
        chk = Check(header.topic)
        expect_type(chk, header, cls.TYPE)
        if buffers:
            chk.fail(f"Diagnostics carries no buffers, got {len(buffers)}")
        v = _check_keys(chk, header.raw)
        return cls(
            stamp=header.stamp,
            node=v["node"],
            level=v["level"],
            message=v["message"],
            counters=v["counters"],
            latencies={k: LatencyStats(**x) for k, x in v["latencies"].items()},
            gauges=v["gauges"],
            frame_id=header.frame_id,
            seq=header.seq,
        )


def _check_keys(chk: Check, raw: dict[str, Any]) -> dict[str, Any]:
    """The Diagnostics keys of a header map, type-checked."""
    out: dict[str, Any] = {}
    for key in ("node", "level", "message"):
        out[key] = chk.as_str(chk.key(raw, key), f"header key '{key}'")
    if out["level"] not in LEVELS:
        chk.fail(f"level {out['level']!r} is not one of {', '.join(LEVELS)}")
    counters = chk.as_map(chk.key(raw, "counters"), "header key 'counters'")
    out["counters"] = {k: chk.as_int(v, f"counters[{short(k)}]") for k, v in counters.items()}
    gauges = chk.as_map(chk.key(raw, "gauges"), "header key 'gauges'")
    out["gauges"] = {k: chk.as_float(v, f"gauges[{short(k)}]") for k, v in gauges.items()}
    latencies = chk.as_map(chk.key(raw, "latencies"), "header key 'latencies'")
    out["latencies"] = {}
    for k, v in latencies.items():
        m = chk.as_map(v, f"latencies[{short(k)}]")
        out["latencies"][k] = {
            q: chk.as_float(
                chk.key(m, q, f"latencies[{short(k)}]"), f"latencies[{short(k)}].{q}", 0.0
            )
            for q in ("p50", "p99")
        }
    return out
