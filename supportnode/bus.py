"""Thin ZeroMQ publish/subscribe helpers: topics, keep-newest input, clear endpoint errors.

A message is a list of frames ``[topic, *payload]`` (what `supportnode.msgs` encodes); this module
knows nothing of what the payload means. Sockets close with linger 0, so closing never blocks on
undelivered messages. Both classes are context managers and share ``zmq.Context.instance()``
unless given a context, which lets ``inproc://`` endpoints reach each other within a process.

Endpoints are ``tcp://host:port`` (``tcp://127.0.0.1:*`` binds a free port; read it back from
``.endpoint``), ``ipc://path`` or ``inproc://name``. Which side binds is a deployment choice; the
convention here is ROS-like: whoever produces a stream that others follow (a sensor driver, the
node's results) binds, and consumers connect.

Sensor-data semantics: a `Subscriber` keeps only the newest ``keep_newest`` messages when its
consumer falls behind. ZMQ_CONFLATE cannot do this for multipart messages (it keeps one *frame*),
so the receive queue is kept small (RCVHWM) and every `Subscriber.recv` first drains all that
has arrived, keeping the newest and counting the rest in ``dropped``.

Message size: ``Subscriber(max_message_bytes=...)`` counts and discards larger messages in
``oversized`` instead of setting ZMQ_MAXMSGSIZE (libzmq treats a larger frame as a protocol error
and drops the connection without reconnecting). Every receiving socket of the project passes a
limit (the node: ``node.max_message_bytes``; `supportnode.client`: its wire limits).

Security (optional): ``curve=CurveKeys(...)`` encrypts and authenticates a socket with CURVE
(`supportnode.curve`: the binding socket is the server and accepts only the clients whose
public keys are in its ``authorized_dir``; the connecting one is the client). A peer without
CURVE, or with a key not authorised, never completes the handshake, so it neither receives
nor delivers anything.

Failed handshakes (optional): ``watch=report`` watches the socket's ZeroMQ monitor
(`supportnode.handshake`): each failure is counted in ``handshake_failures()`` by kind and
reported through ``report`` (one line, once per peer host and kind, naming the peer); a
connecting socket whose session libzmq ended after a mechanism mismatch or a refused key is
reconnected (in `Subscriber.recv` / `Publisher.send`, its owner's thread), so that the right
peer is heard again once it is there.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeAlias

import zmq

from supportnode._closing import Closing
from supportnode.curve import CurveKeys, configure_curve, release_curve
from supportnode.endpoints import attach, check_endpoint
from supportnode.errors import BusError
from supportnode.handshake import HandshakeWatch

__all__ = [
    "BusError",
    "CurveKeys",
    "Frames",
    "Publisher",
    "Subscriber",
    "Tap",
    "check_endpoint",
    "publisher_when_free",
]

#: One multipart message: ``[topic, *payload]``. Received payload frames are zero-copy views.
Frames: TypeAlias = "list[bytes | memoryview]"

# Upper bound of messages drained in one recv: a publisher faster than draining must not keep a
# consumer in the drain loop forever.
_MAX_DRAIN = 10_000
# How long a drain that emptied a full receive queue waits for ZeroMQ to refill it.
_REFILL_WAIT_MS = 5
# Longest single wait of a receive. Python runs a signal handler between bytecodes: a SIGINT
# that lands just before the poll call would otherwise wait for the next message, forever on a
# quiet topic (an example program ignored Ctrl-C that way, now and then).
_WAIT_SLICE_MS = 100


class _Socket(Closing):
    """Shared life cycle: one socket, linger 0, closed by `close` or leaving a ``with`` block."""

    def __init__(self, kind: int, context: zmq.Context | None) -> None:
        self._context = context if context is not None else zmq.Context.instance()
        self.socket: zmq.Socket = self._context.socket(kind)
        # linger 0: closing (or Ctrl-C) never waits for a peer that may never read.
        self.socket.setsockopt(zmq.LINGER, 0)
        self.endpoint = ""
        self._zap_domain = ""  # set while this socket is a CURVE server
        self._watch: HandshakeWatch | None = None

    def _attach(self, endpoint: str, bind: bool, watch: Callable[[str], None] | None) -> None:
        """Bind or connect, watching the handshakes when asked (`supportnode.handshake`): the
        monitor first, since a connection to a peer already there may fail at once."""
        if watch is not None:
            kind = "subscriber" if self.socket.type == zmq.SUB else "publisher"
            self._watch = HandshakeWatch(
                self.socket, endpoint, name=kind, connects=not bind, report=watch
            )
        self.endpoint = attach(self.socket, endpoint, bind)
        if self._watch is not None:
            self._watch.endpoint = self.endpoint  # the port bound for tcp://host:*

    def handshake_failures(self) -> dict[str, int]:
        """Failed handshakes by kind (`supportnode.handshake.KINDS`); empty when not watched."""
        return self._watch.failures() if self._watch is not None else {}

    def keep_connected(self) -> None:
        """A new session to the endpoint after a failed handshake ended the last one, when
        one is due (`recv` and `send` call it; so do readers of ``socket`` itself)."""
        if self._watch is None or not self._watch.reconnect_due():
            return
        try:
            self.socket.disconnect(self.endpoint)
        except zmq.ZMQError:
            pass  # libzmq forgot the endpoint with its session: connecting is what counts
        self.socket.connect(self.endpoint)

    def _setup_curve(self, curve: CurveKeys | None, bind: bool) -> None:
        """Configure CURVE before bind/connect: server if binding, else client."""
        if curve is not None:
            self._zap_domain = configure_curve(self.socket, self._context, curve, bind)

    def close(self) -> None:
        """Close the socket now, discarding anything unsent (idempotent)."""
        if self._watch is not None:
            if not self.socket.closed:
                self.socket.disable_monitor()
            self._watch.close()
            self._watch = None
        if not self.socket.closed:
            self.socket.close(linger=0)
        if self._zap_domain:
            domain, self._zap_domain = self._zap_domain, ""
            release_curve(self._context, domain)

    @property
    def closed(self) -> bool:
        return bool(self.socket.closed)

    def _fail_init(self) -> None:
        """Close the socket when the constructor fails after creating it."""
        self.close()


class Publisher(_Socket):
    """A PUB socket sending multipart messages without copying their buffers.

    ``hwm`` messages queue per subscriber before newer ones are dropped for that subscriber
    (a publisher never blocks on a slow consumer). ``endpoint`` holds the resolved address.
    ``curve``: optional CURVE keys (server when binding, client when connecting).
    ``watch``: report failed handshakes through it (see the module docstring).
    ``check``: called with each message of our topics within the size limit as it comes off
    the socket; it returns what to keep in the message's place (what `recv` then returns), or
    None to refuse the message (counted in ``refused``; the check reports why). Refused messages
    take no place in the queue: a stream of malformed messages cannot push out the newest good
    one.
    """

    def __init__(
        self,
        endpoint: str,
        bind: bool = True,
        context: zmq.Context | None = None,
        *,
        hwm: int = 100,
        curve: CurveKeys | None = None,
        watch: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(zmq.PUB, context)
        try:
            self.socket.setsockopt(zmq.SNDHWM, hwm)
            self._setup_curve(curve, bind)
            self._attach(endpoint, bind, watch)
        except BaseException:
            self._fail_init()
            raise

    def __enter__(self) -> Publisher:
        return self

    def send(self, frames: Sequence[bytes | memoryview | zmq.Frame]) -> None:
        """Send one message ``[topic, *payload]``; buffers are sent zero-copy, so callers must
        not modify them afterwards (numpy arrays: send a copy if you will reuse the array)."""
        if not frames:
            raise ValueError("a message needs at least a topic frame")
        self.keep_connected()
        self.socket.send_multipart(list(frames), copy=False)


def publisher_when_free(endpoint: str, wait_s: float = 2.0, **kw: Any) -> Publisher:
    """A `Publisher` binding ``endpoint``, retried for ``wait_s`` while the address is in use:
    libzmq frees a closed socket's port asynchronously, so a driver restarted at once may find
    its port still taken for a moment. ``kw``: as for Publisher."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            return Publisher(endpoint, bind=True, **kw)
        except BusError as err:
            if "address already in use" not in str(err) or time.monotonic() > deadline:
                raise
            time.sleep(0.05)


class Subscriber(_Socket):
    """A SUB socket receiving messages of exactly the given topics, keeping the newest.

    ``topics``: one topic or several (str or bytes). ZeroMQ filters by prefix, so frame 0 is also
    compared exactly: subscribing to ``scan`` never yields ``scan2``. ``keep_newest``: how many
    messages of each topic are kept when the consumer is slower than the publisher; older ones
    are dropped and counted in ``dropped`` (messages lost earlier, in a full publisher queue,
    cannot be counted). Kept messages come out oldest first, topics interleaved as they came.
    ``max_message_bytes``: larger messages are discarded and counted in ``oversized``. (Not
    ZMQ_MAXMSGSIZE: libzmq takes a larger frame for a protocol error and closes the connection
    for good, without reconnecting, so one oversized scan would cut a node off its sensor.)
    ``rcvhwm``: messages ZeroMQ queues before holding back the sender (default: topics x
    keep_newest + 4). It bounds the memory of unread scans; messages held back wait in the
    publisher's queue (its ``hwm``), which is why sensor publishers keep that small too.
    ``curve``: optional CURVE keys (server when binding, client when connecting).
    ``watch``: report failed handshakes through it (see the module docstring).
    """

    def __init__(
        self,
        endpoint: str,
        topics: str | bytes | Sequence[str | bytes],
        bind: bool = False,
        keep_newest: int = 1,
        context: zmq.Context | None = None,
        *,
        max_message_bytes: int | None = None,
        rcvhwm: int | None = None,
        curve: CurveKeys | None = None,
        check: Callable[[Frames], Any] | None = None,
        watch: Callable[[str], None] | None = None,
    ) -> None:
        if keep_newest < 1:
            raise ValueError(f"keep_newest must be at least 1, got {keep_newest}")
        if isinstance(topics, (str, bytes)):
            topics = [topics]
        self.topics = frozenset(t.encode() if isinstance(t, str) else bytes(t) for t in topics)
        if not self.topics:
            raise ValueError("subscribe to at least one topic")
        self.keep_newest = keep_newest
        self.rcvhwm = rcvhwm if rcvhwm is not None else len(self.topics) * keep_newest + 4
        self.max_message_bytes = max_message_bytes
        self.dropped = 0  # older messages discarded because newer ones arrived
        self.oversized = 0  # messages above max_message_bytes
        self.last_oversized: tuple[bytes, int] | None = None  # (topic, bytes) of the latest
        self.received = 0  # messages of our topics taken off the socket
        self.refused = 0  # messages that ``check`` refused
        self._check = check
        # (topic, message or what check made of it), oldest first
        self._pending: collections.deque[tuple[bytes, Any]] = collections.deque()
        super().__init__(zmq.SUB, context)
        try:
            # A small receive queue bounds the memory held by unread (large) scans; drain
            # does the dropping. Too small and stale scans wait in the publisher's queue.
            self.socket.setsockopt(zmq.RCVHWM, self.rcvhwm)
            for topic in sorted(self.topics):
                self.socket.setsockopt(zmq.SUBSCRIBE, topic)
            self._setup_curve(curve, bind)
            self._attach(endpoint, bind, watch)
        except BaseException:
            self._fail_init()
            raise

    def __enter__(self) -> Subscriber:
        return self

    @property
    def pending(self) -> int:
        """Messages received and kept but not yet returned by `recv`."""
        return len(self._pending)

    def recv(self, timeout_s: float | None = None, wake: int | None = None) -> Frames | Any | None:
        """The oldest kept message after draining the socket, or None after ``timeout_s``.

        ``timeout_s``: None waits forever, 0 only looks. Frame 0 is the topic (bytes); payload
        frames are zero-copy memoryviews valid as long as they are referenced. With a
        ``check``: what it returned for the message. ``wake``: a file descriptor (a socket's)
        waited on as well: None as soon as it is readable (the caller reads it).
        """
        deadline = None if timeout_s is None else time.monotonic() + max(0.0, timeout_s)
        poller = None
        if wake is not None:
            poller = zmq.Poller()
            poller.register(self.socket, zmq.POLLIN)
            poller.register(wake, zmq.POLLIN)
        while True:
            self.keep_connected()
            self._drain()
            if self._pending:
                return self._pending.popleft()[1]
            if deadline is None:
                wait_ms = _WAIT_SLICE_MS
            else:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                wait_ms = min(max(1, int(left * 1000)), _WAIT_SLICE_MS)
            # A wake-up may bring only other topics' messages: loop until the deadline.
            if poller is None:
                self.socket.poll(wait_ms, zmq.POLLIN)
            elif wake in dict(poller.poll(wait_ms)):
                return None

    def _drain(self) -> None:
        """Move everything that has arrived into the kept queue, dropping the oldest.

        A pass that empties a (nearly) full receive queue means ZeroMQ may be holding back more
        (the queue is only ``rcvhwm`` deep, and libzmq stops reading at about half of that):
        wait a moment for its I/O thread to refill the queue and drain again, so that what we
        keep really is the newest. A consumer that keeps up never waits here.
        """
        refill_at = max(2, self.rcvhwm // 2)
        total = 0
        while total < _MAX_DRAIN:
            count = 0
            while total + count < _MAX_DRAIN:
                try:
                    parts = self.socket.recv_multipart(zmq.NOBLOCK, copy=False)
                except zmq.Again:
                    break
                count += 1
                self._keep(parts)
            total += count
            if count < refill_at or not self.socket.poll(_REFILL_WAIT_MS, zmq.POLLIN):
                return

    def _keep(self, parts: list[zmq.Frame]) -> None:
        """Queue one received message if it is of our topics and within the size limit."""
        topic = parts[0].bytes
        if topic not in self.topics:
            return  # a prefix match of another topic (scan2 for scan)
        self.received += 1
        if self.max_message_bytes is not None:
            size = sum(len(p) for p in parts)
            if size > self.max_message_bytes:
                self.oversized += 1
                self.last_oversized = (topic, size)
                return
        frames: Frames = [topic, *(p.buffer for p in parts[1:])]
        item = frames if self._check is None else self._check(frames)
        if item is None:
            self.refused += 1
            return
        self._pending.append((topic, item))
        # Per topic, like one ROS subscription queue each: a burst of obstacles must not push
        # out the newest surfaces. The queue holds at most topics x keep_newest messages.
        if sum(1 for t, _ in self._pending if t == topic) > self.keep_newest:
            for i, (old, _) in enumerate(self._pending):
                if old == topic:
                    del self._pending[i]
                    self.dropped += 1
                    break


class Tap(_Socket):
    """A SUB socket for tools that stamp and count each message as it comes off the socket
    (``hz``, ``record``): ``prefixes`` are ZeroMQ's own topic filters (empty: every topic; no
    exact match, no keep-newest), ``rcvhwm`` a deep receive queue. Read ``socket`` directly
    and call `keep_connected` between reads. ``curve`` and ``watch`` as for `Subscriber`."""

    def __init__(
        self,
        endpoint: str,
        prefixes: Sequence[bytes] = (),
        bind: bool = False,
        context: zmq.Context | None = None,
        *,
        rcvhwm: int = 10_000,
        curve: CurveKeys | None = None,
        watch: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(zmq.SUB, context)
        try:
            self.socket.setsockopt(zmq.RCVHWM, rcvhwm)
            for prefix in sorted(prefixes) or [b""]:
                self.socket.setsockopt(zmq.SUBSCRIBE, prefix)
            self._setup_curve(curve, bind)
            self._attach(endpoint, bind, watch)
        except BaseException:
            self._fail_init()
            raise

    def __enter__(self) -> Tap:
        return self
