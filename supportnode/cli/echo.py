"""`supportnode echo TOPIC`: print each message of a topic, decoded, as a readable block or as
one JSON object per line (``--json``).

Connects to a publisher's endpoint (the node's results by default). Every message is shown (no
keep-newest dropping unless the terminal falls far behind); arrays are summarised, never
dumped. A malformed message is reported as one line on stderr and echo goes on. Ends after
``--count`` messages, after ``--timeout`` seconds without a message, or on Ctrl-C (exit 0).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

# numpy only: this module is imported just when `echo` runs (see supportnode.cli.build_parser).
import numpy as np

from supportnode.cli._common import (
    add_curve_arguments,
    curve_keys,
    handshake_report,
    int_at_least,
    positive_seconds,
)

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5556"
# Messages kept when printing falls behind (a slow terminal); older ones are dropped.
_KEEP_NEWEST = 1000
# Silence after which echo says what it waits for, s.
_QUIET_S = 2.0
# A stamp within this of the receive time is wall-clock time and gets an age; others
# (simulated time, a replay without --restamp) would show a meaningless one, s.
_NEAR_NOW_S = 600.0
# Arrays up to this many elements appear in full in --json output; larger ones as dtype/shape.
_SMALL_ARRAY = 16


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("topic", help="topic to print, e.g. surfaces, obstacles, scan")
    parser.add_argument(
        "--endpoint",
        default=DEFAULT_ENDPOINT,
        help=f"publisher endpoint to connect to (default {DEFAULT_ENDPOINT})",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object per message per line")
    parser.add_argument("--count", type=int_at_least(1), metavar="N", help="stop after N messages")
    parser.add_argument(
        "--timeout",
        type=positive_seconds,
        metavar="S",
        help="stop after S seconds without a message (default: wait forever)",
    )
    add_curve_arguments(parser)


def run(args: argparse.Namespace) -> int:
    import json
    import sys
    import time

    from supportnode import bus
    from supportnode.errors import ProtocolError
    from supportnode.msgs import Limits, decode_any

    limits = Limits()
    shown = 0
    try:
        with bus.Subscriber(
            args.endpoint,
            args.topic,
            keep_newest=_KEEP_NEWEST,
            max_message_bytes=limits.max_message_bytes,
            rcvhwm=64,
            curve=curve_keys(args, bind=False),
            watch=handshake_report("echo"),  # says why nothing comes from a CURVE node
        ) as sub:
            oversized = 0
            waiting = f"messages on topic {args.topic!r} from {args.endpoint}"
            while args.count is None or shown < args.count:
                frames = _recv_announcing(sub, args.timeout, waiting if shown == 0 else None)
                if sub.oversized != oversized and sub.last_oversized is not None:
                    oversized = sub.oversized
                    topic, size = sub.last_oversized
                    print(
                        f"supportnode echo: topic {topic.decode('utf-8', 'replace')!r}: message "
                        f"of {size} bytes exceeds max_message_bytes {limits.max_message_bytes}",
                        file=sys.stderr,
                        flush=True,
                    )
                if frames is None:
                    break  # --timeout without a message
                received = time.time()
                size = sum(_nbytes(f) for f in frames)
                try:
                    msg = decode_any(frames, limits)
                except ProtocolError as err:
                    print(f"supportnode echo: skipped: {err}", file=sys.stderr, flush=True)
                    continue
                if args.json:
                    obj = to_json(msg, args.topic, size)
                    line = json.dumps(obj, separators=(",", ":"), allow_nan=False)
                    print(line, flush=True)
                else:
                    print(format_message(msg, args.topic, size, received), flush=True)
                shown += 1
    except KeyboardInterrupt:
        pass
    except BrokenPipeError:  # `supportnode echo ... | head`
        sys.stderr.close()
    return 0


def _recv_announcing(sub: Any, timeout: float | None, waiting: str | None) -> Any:
    """``sub.recv(timeout)``; when ``waiting`` is given and 2 s pass in silence, says on
    stderr what echo waits for (a wrong endpoint or topic shows at once, not never)."""
    import sys

    if waiting is None or (timeout is not None and timeout <= _QUIET_S):
        return sub.recv(timeout)
    frames = sub.recv(_QUIET_S)
    if frames is not None:
        return frames
    print(
        f"supportnode echo: waiting for {waiting} (nothing for {_QUIET_S:.0f} s; "
        "is the publisher running, and is this its endpoint and topic?)",
        file=sys.stderr,
        flush=True,
    )
    return sub.recv(None if timeout is None else timeout - _QUIET_S)


# --- text -----------------------------------------------------------------------------------


def format_message(msg: Any, topic: str, size: int, received: float | None = None) -> str:
    """A readable block for one decoded message (ends with a ``---`` line)."""
    from supportnode.msgs import Diagnostics, ObstacleClusters, PointCloud, SupportSurfaces

    near = received is not None and abs(received - msg.stamp) < _NEAR_NOW_S
    age = f"  (age {received - msg.stamp:.3f} s)" if near else ""
    lines = [
        f"topic: {topic}  type: {type(msg).__name__}  seq: {msg.seq}  bytes: {size}",
        f"stamp: {msg.stamp:.6f}{age}  frame_id: {msg.frame_id or '-'}",
    ]
    if isinstance(msg, PointCloud):
        fields = " ".join(f"{k}:{_dtype_shape(v)}" for k, v in msg.fields.items())
        lines.append(f"points: {msg.count}  fields: {fields}")
        if msg.dropped_nonfinite:
            lines.append(f"dropped non-finite points: {msg.dropped_nonfinite}")
        if msg.pose is not None:
            lines.append(f"pose: t {_vec(msg.pose.translation)}  q {_vec(msg.pose.rotation)}")
        if msg.gravity is not None:
            lines.append(f"gravity: {_vec(msg.gravity)}")
        if msg.imu_orientation is not None:
            lines.append(f"imu_orientation: {_vec(msg.imu_orientation)}")
    elif isinstance(msg, SupportSurfaces):
        lines.append(f"surfaces: {len(msg.surfaces)}")
        for s in msg.surfaces:
            if math.isnan(s.disc_radius):
                free = "free disc n/a"
            elif s.disc_radius <= 0 or not bool(np.isfinite(s.disc_center).all()):
                free = "free disc none"
            else:
                free = f"free disc r {s.disc_radius:.3f} m at {_vec(s.disc_center, 2)}"
            lines.append(
                f"  id {s.id}  height {s.height:.3f} m  area {s.area:.3f} m2  {free}  "
                f"safe {'yes' if s.safe else 'no'}  points {s.point_count}"
            )
    elif isinstance(msg, ObstacleClusters):
        lines.append(f"clusters: {len(msg.clusters)}")
        for c in msg.clusters:
            size_txt = " x ".join(f"{v:.3f}" for v in np.asarray(c.obb_size).tolist())
            lines.append(
                f"  id {c.id}  surface {'-' if c.surface_id is None else c.surface_id}  "
                f"centroid {_vec(c.centroid)}  size {size_txt} m  height {c.height:.3f} m  "
                f"points {c.point_count}"
            )
    elif isinstance(msg, Diagnostics):
        lines.append(f"node: {msg.node}  level: {msg.level}  message: {msg.message or '-'}")
        if msg.counters:
            lines.append("counters: " + "  ".join(f"{k}={v}" for k, v in msg.counters.items()))
        for k, v in msg.latencies.items():
            lines.append(f"  latency {k}: p50 {v.p50 * 1e3:.2f} ms  p99 {v.p99 * 1e3:.2f} ms")
        if msg.gauges:
            lines.append("gauges: " + "  ".join(f"{k}={v:.4g}" for k, v in msg.gauges.items()))
    lines.append("---")
    return "\n".join(lines)


def _vec(values: Any, digits: int = 3) -> str:
    return "(" + ", ".join(f"{v:.{digits}f}" for v in np.asarray(values).ravel().tolist()) + ")"


def _dtype_shape(a: np.ndarray) -> str:
    a = np.asarray(a)
    return str(a.dtype) if a.ndim == 1 else f"{a.dtype}{list(a.shape[1:])}"


# --- JSON -----------------------------------------------------------------------------------


def to_json(msg: Any, topic: str, size: int) -> dict[str, Any]:
    """A JSON-ready dict for one message: plain Python types only, non-finite floats as None,
    arrays larger than a few elements summarised as ``{"dtype", "shape"}``."""
    from supportnode.msgs import Diagnostics, ObstacleClusters, PointCloud, SupportSurfaces

    out: dict[str, Any] = {
        "topic": topic,
        "type": type(msg).__name__,
        "seq": msg.seq,
        "stamp": msg.stamp,
        "frame_id": msg.frame_id,
        "bytes": size,
    }
    if isinstance(msg, PointCloud):
        out.update(_cloud_json(msg))
    elif isinstance(msg, SupportSurfaces):
        out["surfaces"] = [_surface_json(s) for s in msg.surfaces]
    elif isinstance(msg, ObstacleClusters):
        out["clusters"] = [_cluster_json(c) for c in msg.clusters]
    elif isinstance(msg, Diagnostics):
        out["node"] = msg.node
        out["level"] = msg.level
        out["message"] = msg.message
        out["counters"] = dict(msg.counters)
        out["latencies"] = {k: {"p50": v.p50, "p99": v.p99} for k, v in msg.latencies.items()}
        out["gauges"] = dict(msg.gauges)
    return _plain(out)


def _cloud_json(msg: Any) -> dict[str, Any]:
    """A PointCloud's fields after the common ones: arrays as dtype and shape."""
    return {
        "count": msg.count,
        "fields": {k: _array_summary(v) for k, v in msg.fields.items()},
        "dropped_nonfinite": msg.dropped_nonfinite,
        "pose": None
        if msg.pose is None
        else {"translation": msg.pose.translation, "rotation": msg.pose.rotation},
        "gravity": msg.gravity,
        "imu_orientation": msg.imu_orientation,
    }


def _surface_json(s: Any) -> dict[str, Any]:
    """One surface of a SupportSurfaces message; its outline as ring and vertex counts."""
    return {
        "id": s.id,
        "height": s.height,
        "normal": s.normal,
        "area": s.area,
        "free_area": s.free_area,
        "disc_center": s.disc_center,
        "disc_radius": s.disc_radius,
        "flatness": s.flatness,
        "point_count": s.point_count,
        "safe": s.safe,
        "outline": {"rings": len(s.outline), "vertices": [len(r) for r in s.outline]},
    }


def _cluster_json(c: Any) -> dict[str, Any]:
    """One cluster of an ObstacleClusters message; its points as dtype and shape."""
    return {
        "id": c.id,
        "surface_id": c.surface_id,
        "centroid": c.centroid,
        "bbox_min": c.bbox_min,
        "bbox_max": c.bbox_max,
        "obb_center": c.obb_center,
        "obb_size": c.obb_size,
        "obb_yaw": c.obb_yaw,
        "height": c.height,
        "point_count": c.point_count,
        "points": None if c.points is None else _array_summary(c.points),
    }


def _array_summary(a: np.ndarray) -> dict[str, Any]:
    a = np.asarray(a)
    return {"dtype": str(a.dtype), "shape": list(a.shape)}


def _plain(value: Any) -> Any:
    """``value`` with numpy types converted, small arrays as lists, large ones summarised and
    NaN/Inf as None (strict JSON has no NaN)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        if value.size > _SMALL_ARRAY:
            return _array_summary(value)
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _nbytes(frame: Any) -> int:
    return frame.nbytes if isinstance(frame, memoryview) else len(frame)
