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

Security (optional): ``curve=CurveKeys(...)`` encrypts and authenticates a socket with CURVE.
The binding socket is the server: it uses its own secret key and accepts only clients whose
public keys (``*.key``) are in ``authorized_dir``, checked by a ZAP handler
(`zmq.auth.thread.ThreadAuthenticator`, one per context, each server socket with its own ZAP
domain). The connecting socket is the client: its own key pair plus the server's public key.
Key pairs are made by ``supportnode keys DIR --name NAME`` (``NAME.key`` public,
``NAME.key_secret`` both). A peer without CURVE, or with a key not authorised, never completes
the handshake, so it neither receives nor delivers anything.

Failed handshakes (optional): ``watch=report`` watches the socket's ZeroMQ monitor
(`supportnode.handshake`): each failure is counted in ``handshake_failures()`` by kind and
reported through ``report`` (one line, once per peer host and kind, naming the peer); a
connecting socket whose session libzmq ended after a mechanism mismatch or a refused key is
reconnected (in `Subscriber.recv` / `Publisher.send`, its owner's thread), so that the right
peer is heard again once it is there.
"""

from __future__ import annotations

import collections
import errno
import itertools
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeAlias

import zmq

from supportnode._closing import Closing
from supportnode.errors import SupportNodeError
from supportnode.handshake import HandshakeWatch

__all__ = ["BusError", "CurveKeys", "Frames", "Publisher", "Subscriber", "check_endpoint"]

#: One multipart message: ``[topic, *payload]``. Received payload frames are zero-copy views.
Frames: TypeAlias = "list[bytes | memoryview]"

_SCHEMES = ("tcp://", "ipc://", "inproc://")
# Upper bound of messages drained in one recv: a publisher faster than draining must not keep a
# consumer in the drain loop forever.
_MAX_DRAIN = 10_000
# How long a drain that emptied a full receive queue waits for ZeroMQ to refill it.
_REFILL_WAIT_MS = 5
# Longest single wait of a receive. Python runs a signal handler between bytecodes: a SIGINT
# that lands just before the poll call would otherwise wait for the next message, forever on a
# quiet topic (an example program ignored Ctrl-C that way, now and then).
_WAIT_SLICE_MS = 100


class BusError(SupportNodeError):
    """A socket cannot bind or connect to an endpoint (bad address, address in use), or its
    CURVE keys cannot be used (missing or unreadable key file)."""


@dataclass(frozen=True)
class CurveKeys:
    """CURVE keys of one socket; which fields are needed depends on whether it binds.

    ``key_file``: this socket's key pair, a ``.key_secret`` file (both sides).
    ``authorized_dir``: server (binding) side: folder of the authorised clients' public keys
    (``*.key``); clients whose key is not there are refused.
    ``server_key``: client (connecting) side: the server's public key file (``.key``).
    """

    key_file: str | os.PathLike[str]
    authorized_dir: str | os.PathLike[str] = ""
    server_key: str | os.PathLike[str] = ""


def _load_key(path: str | os.PathLike[str], need_secret: bool) -> tuple[bytes, bytes | None]:
    """(public, secret) z85 keys of a certificate file, or a one-line BusError naming it."""
    import zmq.auth

    name = os.fspath(path)
    if not name:
        raise BusError("CURVE: no key file given")
    if not os.path.isfile(name):
        raise BusError(f"{name}: CURVE key file not found")
    try:
        with open(name, "rb"):
            pass
        public, secret = zmq.auth.load_certificate(name)
    except OSError as err:
        raise BusError(f"{name}: cannot read CURVE key file ({err.strerror or err})") from err
    except ValueError as err:
        raise BusError(f"{name}: not a CURVE certificate (no public-key)") from err
    if need_secret and not secret:
        raise BusError(
            f"{name}: holds no secret key (use the .key_secret file made by `supportnode keys`)"
        )
    return public, secret


def _load_authorized(folder: str | os.PathLike[str]) -> None:
    """Check every ``*.key`` in ``folder`` loads; one-line BusError naming the culprit."""
    name = os.fspath(folder)
    if not name:
        raise BusError("CURVE server: no authorized_dir given (folder of clients' *.key)")
    if not os.path.isdir(name):
        raise BusError(f"{name}: CURVE authorised-keys folder not found")
    for entry in sorted(os.listdir(name)):
        if entry.endswith(".key"):
            _load_key(os.path.join(name, entry), need_secret=False)


# One ZAP handler (ThreadAuthenticator) per context, shared by that context's CURVE servers;
# each server socket gets its own ZAP domain so it accepts only its own folder's keys.
_auth_lock = threading.Lock()
_auths: dict[int, tuple[zmq.Context, Any, int]] = {}
_domains = itertools.count()


def _auth_acquire(context: zmq.Context, folder: str) -> str:
    """Start (or share) the context's authenticator; returns the new socket's ZAP domain."""
    from zmq.auth.thread import ThreadAuthenticator

    domain = f"supportnode.{os.getpid()}.{next(_domains)}"
    with _auth_lock:
        ctx, auth, users = _auths.get(id(context), (context, None, 0))
        if auth is None:
            auth = _start_authenticator(ThreadAuthenticator, context)
        try:
            auth.configure_curve(domain=domain, location=folder)
        except (OSError, ValueError) as err:
            if users == 0:
                auth.stop()
            raise BusError(f"{folder}: cannot load CURVE public keys ({err})") from err
        _auths[id(context)] = (ctx, auth, users + 1)
    return domain


def _start_authenticator(factory: Any, context: zmq.Context) -> Any:
    """Start a ZAP handler. libzmq frees the handler's inproc address asynchronously after a
    previous handler stopped, so binding may briefly find it in use: retry for up to 2 s."""
    deadline = time.monotonic() + 2.0
    while True:
        auth = factory(context)
        try:
            auth.start()
            return auth
        except zmq.ZMQError as err:
            if err.errno != zmq.EADDRINUSE or time.monotonic() > deadline:
                raise BusError(f"cannot start the CURVE authenticator: {err}") from err
            time.sleep(0.02)


def _auth_release(context: zmq.Context, domain: str) -> None:
    """Forget ``domain``; stop the context's authenticator when no server uses it."""
    with _auth_lock:
        entry = _auths.get(id(context))
        if entry is None:
            return
        ctx, auth, users = entry
        auth.certs.pop(domain, None)
        if users <= 1:
            del _auths[id(context)]
            auth.stop()
        else:
            _auths[id(context)] = (ctx, auth, users - 1)


def check_endpoint(endpoint: str) -> str:
    """``endpoint`` unchanged if it is a tcp://, ipc:// or inproc:// address, else a BusError."""
    if not isinstance(endpoint, str) or not endpoint.startswith(_SCHEMES):
        raise BusError(
            f"{endpoint!r}: unsupported endpoint (expected tcp://host:port, ipc://path "
            "or inproc://name)"
        )
    if endpoint.startswith("tcp://") and ":" not in endpoint[len("tcp://") :]:
        raise BusError(f"{endpoint}: tcp endpoint without a port (expected tcp://host:port)")
    return endpoint


def _attach(sock: zmq.Socket, endpoint: str, bind: bool) -> str:
    """Bind or connect ``sock``; returns the resolved endpoint (the actual port for ``:*``)."""
    check_endpoint(endpoint)
    try:
        if bind:
            sock.bind(endpoint)
            return str(sock.getsockopt_string(zmq.LAST_ENDPOINT)) or endpoint
        sock.connect(endpoint)
        return endpoint
    except zmq.ZMQError as err:
        verb = "bind" if bind else "connect"
        if err.errno == errno.EADDRINUSE:
            raise BusError(f"{endpoint}: address already in use") from err
        if err.errno == errno.EADDRNOTAVAIL:
            raise BusError(f"{endpoint}: cannot {verb}: no such local address") from err
        if err.errno == errno.EACCES:
            raise BusError(f"{endpoint}: cannot {verb}: permission denied") from err
        raise BusError(f"{endpoint}: cannot {verb} ({err.strerror})") from err


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
        """Bind or connect, then watch the handshakes when asked (`supportnode.handshake`)."""
        self.endpoint = _attach(self.socket, endpoint, bind)
        if watch is not None:
            kind = "subscriber" if self.socket.type == zmq.SUB else "publisher"
            self._watch = HandshakeWatch(
                self.socket, self.endpoint, name=kind, connects=not bind, report=watch
            )

    def handshake_failures(self) -> dict[str, int]:
        """Failed handshakes by kind (`supportnode.handshake.KINDS`); empty when not watched."""
        return self._watch.failures() if self._watch is not None else {}

    def _reconnect_if_due(self) -> None:
        """A new session to the endpoint after a failed handshake ended the last one."""
        if self._watch is None or not self._watch.reconnect_due():
            return
        try:
            self.socket.disconnect(self.endpoint)
        except zmq.ZMQError:
            pass  # libzmq forgot the endpoint with its session: connecting is what counts
        self.socket.connect(self.endpoint)

    def _setup_curve(self, curve: CurveKeys | None, bind: bool) -> None:
        """Configure CURVE before bind/connect: server if binding, else client."""
        if curve is None:
            return
        if not zmq.has("curve"):
            raise BusError("CURVE requested but this libzmq was built without CURVE support")
        public, secret = _load_key(curve.key_file, need_secret=True)
        assert secret is not None  # _load_key raised otherwise
        try:
            if bind:
                _load_authorized(curve.authorized_dir)
                self.socket.setsockopt(zmq.CURVE_SERVER, 1)
                self.socket.setsockopt(zmq.CURVE_SECRETKEY, secret)
                self._zap_domain = _auth_acquire(self._context, os.fspath(curve.authorized_dir))
                self.socket.setsockopt_string(zmq.ZAP_DOMAIN, self._zap_domain)
                # Without this, libzmq accepts every CURVE client while no ZAP handler is
                # bound (e.g. while the shared authenticator restarts): fail closed instead.
                self.socket.setsockopt(zmq.ZAP_ENFORCE_DOMAIN, 1)
            else:
                if not os.fspath(curve.server_key):
                    raise BusError("CURVE client: no server_key given (the server's .key file)")
                server_public, _ = _load_key(curve.server_key, need_secret=False)
                self.socket.setsockopt(zmq.CURVE_PUBLICKEY, public)
                self.socket.setsockopt(zmq.CURVE_SECRETKEY, secret)
                self.socket.setsockopt(zmq.CURVE_SERVERKEY, server_public)
        except zmq.ZMQError as err:
            raise BusError(f"{os.fspath(curve.key_file)}: invalid CURVE key ({err})") from err

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
            _auth_release(self._context, domain)

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
        self._reconnect_if_due()
        self.socket.send_multipart(list(frames), copy=False)


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

    def recv(self, timeout_s: float | None = None) -> Frames | Any | None:
        """The oldest kept message after draining the socket, or None after ``timeout_s``.

        ``timeout_s``: None waits forever, 0 only looks. Frame 0 is the topic (bytes); payload
        frames are zero-copy memoryviews valid as long as they are referenced. With a
        ``check``: what it returned for the message.
        """
        deadline = None if timeout_s is None else time.monotonic() + max(0.0, timeout_s)
        while True:
            self._reconnect_if_due()
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
            if not self.socket.poll(wait_ms, zmq.POLLIN) and deadline is not None:
                if time.monotonic() >= deadline:
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
