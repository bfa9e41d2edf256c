"""Which web pages may open the live view: an ``Origin`` check in front of the Foxglove server.

A browser sends any page's WebSocket requests to ``ws://127.0.0.1:8765`` with the page's
``Origin``; the Foxglove SDK's server (0.30, the newest release) accepts every origin, so any
site open in a local browser could subscribe to the robot's scans and map. `OriginRelay`
listens where the user asked, reads each connection's HTTP upgrade request, and either answers
403 (origin not allowed, reported once per origin) or forwards the connection byte for byte to
the Foxglove server. Allowed by default: the Foxglove app (`FOXGLOVE_ORIGINS`), pages served from
this machine (``http(s)://localhost``, ``127.0.0.1``, ``[::1]``, any port), the desktop app
(``file://``) and clients that send no ``Origin`` (not browsers: a page cannot leave it out);
more by option (``--allow-origin``, ``*`` for any).

The Foxglove server itself listens on 127.0.0.1 on a port browsers refuse to connect to (the
Fetch standard's "bad ports", `HIDDEN_PORTS`), so no page can reach it past the relay; when all
of those are taken it takes any port and `serve` says the check can be bypassed there.
"""

from __future__ import annotations

import selectors
import socket
import threading
from collections.abc import Callable, Sequence
from urllib.parse import urlsplit

__all__ = ["FOXGLOVE_ORIGINS", "HIDDEN_PORTS", "OriginRelay", "origin_allowed"]

FOXGLOVE_ORIGINS = ("https://app.foxglove.dev", "https://embed.foxglove.dev")
_LOCAL_HOSTS = ("localhost", "127.0.0.1", "::1")
#: Unprivileged ports of the Fetch standard's port blocking list: no browser connects to them.
HIDDEN_PORTS = (6566, 6665, 6666, 6667, 6668, 6669, 6679, 6697, 10080, 4190, 5060, 5061, 6000)
_MAX_HEAD = 16 << 10  # bytes of an upgrade request's head
_HEAD_TIMEOUT_S = 5.0
_CHUNK = 1 << 16
_MAX_REPORTED = 64


def origin_allowed(origin: str | None, extra: Sequence[str] = ()) -> bool:
    """Whether a WebSocket request with this ``Origin`` header (None: none sent) may connect."""
    if origin is None or "*" in extra:
        return True
    origin = origin.strip()
    if origin == "file://":
        return True  # the Foxglove desktop app (a page loaded from a file)
    if origin in FOXGLOVE_ORIGINS or origin in (o.rstrip("/") for o in extra):
        return True
    try:
        parts = urlsplit(origin)
    except ValueError:
        return False
    return parts.scheme in ("http", "https") and parts.hostname in _LOCAL_HOSTS


def _origin(head: bytes) -> str | None:
    """The ``Origin`` header of an HTTP request head (None when absent)."""
    for line in head.split(b"\r\n")[1:]:
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == b"origin":
            return value.strip().decode("latin-1")
    return None


class OriginRelay:
    """Accepts on ``host:port`` (0: any free port; the one taken is ``port``) and forwards
    allowed connections to ``target`` (host, port). ``report`` gets one line per refused
    origin (the first time). `close` ends it and every connection."""

    def __init__(
        self,
        host: str,
        port: int,
        target: tuple[str, int],
        allow: Sequence[str] = (),
        report: Callable[[str], None] | None = None,
    ) -> None:
        self.target, self.allow = target, tuple(allow)
        self.report = report or (lambda line: None)
        self.refused = 0
        self._reported: set[str] = set()
        self._lock = threading.Lock()
        self._open: set[socket.socket] = set()
        self._listener = socket.create_server((host, port), reuse_port=False)
        self._listener.settimeout(0.2)
        self.port = int(self._listener.getsockname()[1])
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, name="view origin relay", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._listener.close()
        with self._lock:
            for s in list(self._open):
                s.close()
            self._open.clear()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with self._lock:
            self._open.add(conn)
        upstream = None
        try:
            head = self._head(conn)
            if head is None:
                return
            origin = _origin(head)
            if not origin_allowed(origin, self.allow):
                self._refuse(conn, str(origin))
                return
            upstream = socket.create_connection(self.target, timeout=5.0)
            with self._lock:
                self._open.add(upstream)
            upstream.sendall(head)
            _pump(conn, upstream, self._stop)
        except OSError:
            pass  # a peer that went away: the connection ends
        finally:
            with self._lock:
                for s in (conn, upstream):
                    if s is not None:
                        self._open.discard(s)
                        s.close()

    def _head(self, conn: socket.socket) -> bytes | None:
        """The request head and whatever came with it, or None (too long, too slow)."""
        conn.settimeout(_HEAD_TIMEOUT_S)
        data = b""
        while b"\r\n\r\n" not in data:
            if len(data) > _MAX_HEAD:
                return None
            chunk = conn.recv(4096)
            if not chunk:
                return None
            data += chunk
        conn.settimeout(None)
        return data

    def _refuse(self, conn: socket.socket, origin: str) -> None:
        with self._lock:
            self.refused += 1
            first = origin not in self._reported and len(self._reported) < _MAX_REPORTED
            self._reported.add(origin)
        if first:
            self.report(
                f"refused a viewer connection from origin {origin} (allowed: the Foxglove app, "
                "localhost, --allow-origin)"
            )
        body = f"origin {origin} is not allowed (supportnode view --allow-origin)\n".encode()
        conn.sendall(
            b"HTTP/1.1 403 Forbidden\r\nContent-Type: text/plain\r\nConnection: close\r\n"
            + f"Content-Length: {len(body)}\r\n\r\n".encode()
            + body
        )


def _pump(a: socket.socket, b: socket.socket, stop: threading.Event) -> None:
    """Copy bytes both ways until either side closes or ``stop`` is set."""
    sel = selectors.DefaultSelector()
    sel.register(a, selectors.EVENT_READ, b)
    sel.register(b, selectors.EVENT_READ, a)
    try:
        while not stop.is_set():
            for key, _ in sel.select(0.2):
                data = key.fileobj.recv(_CHUNK)  # type: ignore[union-attr]
                if not data:
                    return
                key.data.sendall(data)
    finally:
        sel.close()
