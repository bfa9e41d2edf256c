"""Failed security handshakes of a ZeroMQ socket, seen through its monitor, and the reconnect
they call for.

A peer whose security mechanism differs from ours (plain meeting CURVE, either way) fails the
ZMTP handshake with a mechanism mismatch; one whose CURVE key a ZAP handler refuses fails with
an authentication error. libzmq then ends that session for good, also on the connecting side:
a node that connected to a misconfigured driver is never heard from that endpoint again, even
after the driver is fixed and restarted, and nothing says why. `HandshakeWatch` reads the
socket's monitor in a thread of its own, counts each failure by kind, reports it in one line
once per peer host and kind (the peer's address: the endpoint when we connect, the accepted
connection's remote address when we bind), and tells the socket's owner when to reconnect a
connecting socket (`reconnect_due`), with a back-off, so that the right peer is heard again.
(A wrong server key fails without detail, and libzmq retries that by itself.)

The watcher thread owns the monitor socket; the watched socket stays with its owner's thread.
"""

from __future__ import annotations

import collections
import os
import socket
import threading
import time
from collections.abc import Callable

import zmq
from zmq.utils.monitor import parse_monitor_message

__all__ = ["KINDS", "HandshakeWatch"]

#: Kinds of failure: mechanism mismatch, refused by ZAP (wrong key), another protocol error
#: (a peer that does not speak ZMTP), no detail (e.g. a CURVE server key that does not match).
KINDS = ("mechanism", "auth", "protocol", "other")
_EVENTS = (
    zmq.EVENT_ACCEPTED
    | zmq.EVENT_DISCONNECTED
    | zmq.EVENT_HANDSHAKE_SUCCEEDED
    | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
    | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
    | zmq.EVENT_HANDSHAKE_FAILED_AUTH
)
_MISMATCH = zmq.PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH
# Reconnect back-off after a failed handshake: from the first to the largest, doubling.
_BACKOFF_S = (0.5, 5.0)
# Hosts remembered as reported (a flood of peers cannot grow memory; beyond it, no more lines).
_MAX_REPORTED = 256
# Open connections whose remote address is remembered (fd -> address) on a binding socket.
_MAX_OPEN = 4096
_POLL_MS = 100
# A binding socket reads a peer's address from the accepted connection; a peer refused within
# microseconds (a mechanism mismatch) may be gone before the watcher thread gets to it.
_GONE = "a peer (address gone before it could be read)"
_MECHANISMS: dict[int, str] = {
    int(zmq.NULL): "no security (plain)",
    int(zmq.PLAIN): "PLAIN",
    int(zmq.CURVE): "CURVE",
}


def _remote_address(fd: int) -> str | None:
    """host:port of the TCP peer of file descriptor ``fd`` (a dup of it: libzmq owns fd)."""
    try:
        with socket.socket(fileno=os.dup(fd)) as s:
            peer = s.getpeername()
    except OSError:
        return None  # closed meanwhile, or not a socket
    if isinstance(peer, tuple) and len(peer) >= 2:
        host = f"[{peer[0]}]" if ":" in str(peer[0]) else str(peer[0])
        return f"{host}:{peer[1]}"
    return None


class HandshakeWatch:
    """Watches ``sock`` (already bound or connected to ``endpoint``) for failed handshakes.

    name: what the socket is, for the report ("scan socket"). connects: the socket connected
    (it is then reconnected after a mechanism or authentication failure). report: called in
    the watcher thread with one line per failure, once per peer host and kind.
    """

    def __init__(
        self,
        sock: zmq.Socket,
        endpoint: str,
        *,
        name: str,
        connects: bool,
        report: Callable[[str], None],
    ) -> None:
        self.endpoint, self.name, self.connects = endpoint, name, connects
        self._report = report
        self._ours = _MECHANISMS.get(int(sock.getsockopt(zmq.MECHANISM)), "another mechanism")
        self._lock = threading.Lock()
        self._failures: collections.Counter[str] = collections.Counter()
        self._reported: set[tuple[str, str]] = set()
        self._open: collections.OrderedDict[int, str] = collections.OrderedDict()
        self._pending: str | None = None  # kind of a failure waiting for its disconnect
        self._backoff = _BACKOFF_S[0]
        self._reconnect_at: float | None = None
        self._monitor = sock.get_monitor_socket(_EVENTS)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"handshakes {name}", daemon=True)
        self._thread.start()

    def failures(self) -> dict[str, int]:
        """Failed handshakes so far, by kind (`KINDS`)."""
        with self._lock:
            return dict(self._failures)

    def reconnect_due(self) -> bool:
        """True once when the owner should reconnect now (``disconnect`` + ``connect``)."""
        with self._lock:
            if self._reconnect_at is None or time.monotonic() < self._reconnect_at:
                return False
            self._reconnect_at = None
            return True

    def close(self) -> None:
        """Stop the watcher thread and close the monitor socket (idempotent). The owner
        disables the monitor on its socket (``disable_monitor``) first, or closes that."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(2.0)

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    if not self._monitor.poll(_POLL_MS):
                        continue
                    event = parse_monitor_message(self._monitor.recv_multipart())
                except zmq.ZMQError:
                    return  # the context is terminating
                if event["event"] == zmq.EVENT_MONITOR_STOPPED:
                    return
                self._on_event(event["event"], int(event["value"]), event["endpoint"])
        finally:
            self._monitor.close(linger=0)

    def _on_event(self, kind: int, value: int, endpoint: bytes) -> None:
        if kind == zmq.EVENT_ACCEPTED:  # first: the address goes with the connection
            self._open[value] = _remote_address(value) or _GONE
            while len(self._open) > _MAX_OPEN:
                self._open.popitem(last=False)
        elif kind == zmq.EVENT_HANDSHAKE_SUCCEEDED:
            self._backoff = _BACKOFF_S[0]
        elif kind == zmq.EVENT_DISCONNECTED:
            peer = self.endpoint if self.connects else self._open.pop(value, _GONE)
            failed, self._pending = self._pending, None
            if failed is not None:
                self._failed(failed, peer)
        else:  # a failed handshake: its connection's disconnect follows, naming it
            if self._pending is not None:
                self._failed(self._pending, self.endpoint if self.connects else _GONE)
            if kind == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
                self._pending = "auth"
            elif kind == zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL:
                self._pending = "mechanism" if value == _MISMATCH else "protocol"
            else:
                self._pending = "other"

    def _failed(self, kind: str, peer: str) -> None:
        again = self.connects and kind in ("mechanism", "auth")
        with self._lock:
            self._failures[kind] += 1
            if again and self._reconnect_at is None:
                self._reconnect_at = time.monotonic() + self._backoff
                self._backoff = min(2 * self._backoff, _BACKOFF_S[1])
        host = peer.rsplit(":", 1)[0]
        if (host, kind) in self._reported or len(self._reported) >= _MAX_REPORTED:
            return
        self._reported.add((host, kind))
        why = {
            "mechanism": f"security mechanism mismatch (this socket uses {self._ours}, the "
            "peer another: configure both sides alike, e.g. both with CURVE keys)",
            "auth": "its key was refused (not among the authorised public keys)",
            "protocol": "the peer does not speak ZMTP",
            "other": "the peer closed the connection"
            + (" (a server key that does not match?)" if self._ours == "CURVE" else ""),
        }[kind]
        then = "; reconnecting" if again else ""
        self._report(
            f"{self.name} {self.endpoint}: handshake with {peer} failed: {why}{then} "
            "(counted; logged once per peer)"
        )
