"""Messages a scan receiver must reject, one or more per reject reason: what a broken or hostile
driver sends. For conformance tests of receivers (the node's fuzz test, a bridge's own tests)
and for ``bench/bench_hostile.py``; the reasons are docs/protocol.md section 9's.

    for reason, messages in rejects(points, stamp=10.0, limits=Limits()).items():
        for frames in messages:
            pub.send(frames)      # each must be counted under `reason`, none may end the node
"""

from __future__ import annotations

import math
from typing import Any

import msgpack
import numpy as np

from supportnode.msgs._wire import Limits
from supportnode.msgs.diagnostics import Diagnostics
from supportnode.msgs.pointcloud import PointCloud

__all__ = ["flipped", "rejects"]

Frames = list[bytes]


def _wire(frames: Any) -> Frames:
    return [bytes(memoryview(f)) for f in frames]


def _reheader(frames: Frames, **changes: Any) -> Frames:
    header = msgpack.unpackb(frames[1], raw=False)
    header.update(changes)
    return [frames[0], msgpack.packb(header, use_bin_type=True), *frames[2:]]


def rejects(
    points: np.ndarray,
    stamp: float,
    limits: Limits,
    topic: str = "scan",
    map_range_m: float = 2e5,
) -> dict[str, list[Frames]]:
    """Messages by the reason a receiver with ``limits`` rejects them. points: (N, 3) metres
    of a good scan (its cloud frame, posed at the origin); stamp: the stream's current time,
    s; map_range_m: a translation beyond the receiver's map (the node: +-105 km)."""

    def cloud(pts: np.ndarray, **kw: Any) -> Frames:
        kw.setdefault("pose", (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])))
        return _wire(PointCloud.from_xyz(pts, kw.pop("stamp", stamp), "lidar", **kw).encode(topic))

    good = cloud(points)
    t = topic.encode()
    big = np.zeros((limits.max_points + 1, 3), np.float32)
    return {
        "malformed": [
            [t, b"\xc1 not msgpack"],
            [t],
            good[:-1],  # a buffer frame missing
            _reheader(good, buffers="x"),
            _reheader(good, stamp="yesterday"),
        ],
        "version": [_reheader(good, version=7)],
        "nonfinite": [
            _reheader(good, stamp=math.inf),
            _reheader(good, gravity=[0.0, math.nan, -9.8]),
        ],
        "bad_gravity": [
            _reheader(good, gravity=[1e308, 1e308, -1e308]),
            _reheader(good, gravity=[0.0, 0.0, -1e-320]),
            _reheader(good, gravity=[0.0, 0.0, 0.0]),
        ],
        "too_many_points": [cloud(big)],
        "oversized": [[*good, bytes(limits.max_message_bytes + 1)]],
        "wrong_type": [_wire(Diagnostics(stamp=stamp, node="impostor").encode(topic))],
        "empty": [cloud(np.zeros((0, 3)))],
        "all_nonfinite": [cloud(np.full((100, 3), np.nan))],
        "out_of_range": [
            cloud(points, pose=([1e300, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])),
            cloud(points, pose=([0.0, map_range_m, 0.0], [0.0, 0.0, 0.0, 1.0])),
        ],
        "stamp_jump": [cloud(points, stamp=stamp + 1e9)],
    }


def flipped(frames: Frames, rng: np.random.Generator, count: int, flips: int = 3) -> list[Frames]:
    """``count`` copies of ``frames`` with ``flips`` random bytes of the header changed."""
    out = []
    for _ in range(count):
        header = bytearray(frames[1])
        for _ in range(flips):
            header[int(rng.integers(len(header)))] = int(rng.integers(256))
        out.append([frames[0], bytes(header), *frames[2:]])
    return out
