"""What a planner or a sensor driver imports: typed publish/subscribe over the supportnode wire.

    from supportnode.client import Publisher, Subscriber

    with Publisher("tcp://127.0.0.1:5555", "scan") as pub:        # a driver: binds, like ROS
        pub.publish_cloud(points, frame_id="lidar", pose=sensor_pose_4x4)

    with Subscriber("surfaces", "tcp://127.0.0.1:5556") as sub:   # a planner: connects
        for msg in sub:                                           # SupportSurfaces, decoded
            ...

Messages that fail to decode or validate are skipped, never raised: ``sub.rejected`` counts them
and ``sub.last_error`` holds the latest `ProtocolError` text. When the consumer is slow, only the
newest ``keep_newest`` messages per topic are kept (``sub.dropped`` counts the rest).

ZeroMQ's PUB/SUB drops what is published before a subscriber's subscription has arrived
(the "slow joiner"): a publisher that binds and sends at once loses its first messages.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import zmq

from supportnode import bus
from supportnode._closing import Closing
from supportnode.errors import ProtocolError
from supportnode.msgs import (
    Diagnostics,
    Limits,
    Message,
    ObstacleClusters,
    PointCloud,
    Pose,
    SupportSurfaces,
    decode_any,
)

__all__ = [
    "Diagnostics",
    "Message",
    "ObstacleClusters",
    "PointCloud",
    "Publisher",
    "Subscriber",
    "SupportSurfaces",
    "pose_from_matrix",
]


class Subscriber(Closing):
    """Decoded messages of one or more topics from ``endpoint``.

    ``topic``: a topic or a list of topics. ``limits``: size limits for decoding (defaults of
    `supportnode.msgs.Limits`). ``timeout``: seconds the iterator waits for a message before it
    stops (None: it waits forever). ``bind``: bind instead of connecting (when publishers
    connect to you). ``keep_newest``: messages kept per topic when you fall behind.
    """

    def __init__(
        self,
        topic: str | Sequence[str],
        endpoint: str,
        limits: Limits | None = None,
        timeout: float | None = None,
        *,
        bind: bool = False,
        keep_newest: int = 1,
        context: zmq.Context[Any] | None = None,
    ) -> None:
        self.limits = limits if limits is not None else Limits()
        self.timeout = timeout
        self._undecodable = 0
        self.last_error: str | None = None  # text of the latest rejection
        self._sub = bus.Subscriber(
            endpoint,
            topic,
            bind=bind,
            keep_newest=keep_newest,
            context=context,
            max_message_bytes=self.limits.max_message_bytes,
        )

    @property
    def endpoint(self) -> str:
        """The resolved endpoint (the actual port after binding ``tcp://host:*``)."""
        return self._sub.endpoint

    @property
    def rejected(self) -> int:
        """Messages skipped as malformed, invalid or larger than ``limits.max_message_bytes``."""
        return self._undecodable + self._sub.oversized

    @property
    def dropped(self) -> int:
        """Messages dropped because newer ones of the same topic arrived first."""
        return self._sub.dropped

    def recv(self, timeout: float | None = None) -> Message | None:
        """The next valid message, or None when none came within ``timeout`` seconds (None:
        wait forever). Malformed messages are counted in ``rejected`` and skipped."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            oversized = self._sub.oversized
            frames = self._sub.recv(left)
            if self._sub.oversized != oversized and self._sub.last_oversized is not None:
                topic, size = self._sub.last_oversized
                self.last_error = (
                    f"topic {topic.decode('utf-8', 'replace')!r}: message of {size} bytes "
                    f"exceeds max_message_bytes {self.limits.max_message_bytes}"
                )
            if frames is None:
                return None
            try:
                return decode_any(frames, self.limits)
            except ProtocolError as err:
                self._undecodable += 1
                self.last_error = str(err)
            if deadline is not None and time.monotonic() >= deadline:
                return None

    def __iter__(self) -> Iterator[Message]:
        """Messages until none arrives within ``timeout`` (forever when it is None)."""
        while (msg := self.recv(self.timeout)) is not None:
            yield msg

    def spin(self, callback: Callable[[Message], object], duration: float | None = None) -> int:
        """Call ``callback(msg)`` for each message for ``duration`` seconds (None: until
        interrupted, e.g. by KeyboardInterrupt); returns how many messages were handled."""
        deadline = None if duration is None else time.monotonic() + duration
        handled = 0
        while True:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                return handled
            msg = self.recv(left)
            if msg is not None:
                callback(msg)
                handled += 1

    def close(self) -> None:
        """Close the socket (idempotent)."""
        self._sub.close()


class Publisher(Closing):
    """Publishes typed messages on one ``topic`` at ``endpoint`` (bound by default: drivers
    bind and the node connects, see `supportnode.params.NodeParams`).

    ``hwm``: messages queued per slow subscriber before newer ones are dropped for it; kept
    small for sensor data, where an old scan is worth less than the next one.
    """

    def __init__(
        self,
        endpoint: str,
        topic: str,
        bind: bool = True,
        *,
        hwm: int = 10,
        context: zmq.Context[Any] | None = None,
    ) -> None:
        self.topic = topic
        self.seq = 0  # sequence number of the last cloud sent by publish_cloud
        self._pub = bus.Publisher(endpoint, bind=bind, context=context, hwm=hwm)

    @property
    def endpoint(self) -> str:
        """The resolved endpoint (the actual port after binding ``tcp://host:*``)."""
        return self._pub.endpoint

    def publish(self, msg: Message, topic: str | None = None) -> None:
        """Encode (which validates) and send ``msg`` on ``topic`` (default: this publisher's);
        raises ProtocolError if it is invalid. One socket may carry several topics, as the
        node's results do."""
        self._pub.send(msg.encode(self.topic if topic is None else topic))

    def publish_cloud(
        self,
        points: np.ndarray,
        stamp: float | None = None,
        frame_id: str = "map",
        fields: Mapping[str, np.ndarray] | None = None,
        pose: Pose | np.ndarray | tuple[np.ndarray, np.ndarray] | None = None,
        gravity: np.ndarray | Sequence[float] | None = None,
    ) -> PointCloud:
        """Send (N, 3) ``points`` (metres, in ``frame_id``) as a PointCloud; returns it.

        ``stamp``: seconds (default: now, wall clock). ``fields``: extra per-point arrays
        (intensity, ring, ...). ``pose``: the sensor's pose in the map frame, as a `Pose`, a
        (translation, quaternion x y z w) pair or a 4x4 homogeneous matrix. ``gravity``: the
        direction of gravity in the cloud frame, when an IMU knows it. Sequence numbers count
        up from 1 per publisher.
        """
        if pose is not None and not isinstance(pose, (Pose, tuple)):
            pose = pose_from_matrix(pose)
        self.seq += 1
        cloud = PointCloud.from_xyz(
            points,
            stamp=time.time() if stamp is None else float(stamp),
            frame_id=frame_id,
            seq=self.seq,
            fields=dict(fields) if fields is not None else None,
            pose=pose,
            gravity=None if gravity is None else np.asarray(gravity, dtype=np.float64),
        )
        self.publish(cloud)
        return cloud

    def close(self) -> None:
        """Close the socket now, discarding anything unsent (idempotent)."""
        self._pub.close()


def pose_from_matrix(matrix: Any) -> Pose:
    """`Pose` from a 4x4 homogeneous transform (rotation part orthonormal, last row 0 0 0 1);
    `InputError` otherwise. The same as `Pose.from_matrix`."""
    return Pose.from_matrix(matrix)
