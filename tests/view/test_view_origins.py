"""`supportnode view` accepts viewers from the Foxglove app's origins and localhost (and clients
that send no Origin: not browsers), others only by --allow-origin: a web page open in a local
browser must not subscribe to the robot's scans. The Foxglove server itself is out of
browsers' reach (a port they refuse)."""

from __future__ import annotations

import base64
import os
import socket

import pytest

pytest.importorskip("foxglove")

import foxglove

from supportnode.view.origins import HIDDEN_PORTS, origin_allowed
from supportnode.view.sink import serve


def _upgrade(port: int, origin: str | None) -> bytes:
    """The status line of the answer to a WebSocket upgrade request with ``origin``."""
    key = base64.b64encode(os.urandom(16)).decode()
    head = (
        f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
        "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n"
        + (f"Origin: {origin}\r\n" if origin is not None else "")
        + "\r\n"
    )
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(head.encode())
        data = b""
        while b"\r\n" not in data:
            chunk = s.recv(4096)
            if not chunk:
                break
            data += chunk
    return data.split(b"\r\n", 1)[0]


@pytest.fixture
def server():
    lines: list[str] = []
    srv = serve(foxglove.Context(), "127.0.0.1", 0, ["https://studio.example.com"], lines.append)
    try:
        yield srv, lines
    finally:
        srv.stop()


@pytest.mark.parametrize(
    "origin",
    [
        None,
        "https://app.foxglove.dev",
        "https://embed.foxglove.dev",
        "http://localhost:8080",
        "http://127.0.0.1",
        "http://[::1]:3000",
        "file://",
        "https://studio.example.com",
    ],
)
def test_allowed_origins_reach_the_foxglove_server(server, origin):
    srv, lines = server
    assert _upgrade(srv.port, origin).startswith(b"HTTP/1.1 101")
    assert lines == []


@pytest.mark.parametrize(
    "origin",
    ["https://evil.example", "null", "http://localhost.evil.example", "https://app.foxglove.dev.x"],
)
def test_other_origins_are_refused_and_reported_once(server, origin):
    srv, lines = server
    for _ in range(3):
        assert _upgrade(srv.port, origin) == b"HTTP/1.1 403 Forbidden"
    assert srv.relay.refused == 3
    assert len(lines) == 1 and origin in lines[0] and "--allow-origin" in lines[0]


def test_the_foxglove_server_is_on_a_port_browsers_refuse(server):
    srv, _ = server
    assert srv.server.port in HIDDEN_PORTS and not srv.exposed


def test_any_origin_by_option():
    assert origin_allowed("https://evil.example", ["*"])
    assert not origin_allowed("https://evil.example", ["https://other.example"])
