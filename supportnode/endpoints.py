"""ZeroMQ endpoints: which addresses are accepted, and binding or connecting with one-line errors.

Endpoints are ``tcp://host:port`` (``tcp://127.0.0.1:*`` binds a free port: `attach` returns
the port bound), ``ipc://path`` or ``inproc://name``. Every failure is a `BusError` naming the
endpoint and what went wrong (address in use, no such local address, permission denied).
"""

from __future__ import annotations

import errno

import zmq

from supportnode.errors import BusError

__all__ = ["attach", "check_endpoint"]

_SCHEMES = ("tcp://", "ipc://", "inproc://")


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


def attach(sock: zmq.Socket, endpoint: str, bind: bool) -> str:
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
