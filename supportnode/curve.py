"""CURVE keys of a socket (`CurveKeys`, `configure_curve`), and the node's key folder.

A binding socket is the server: it uses its own secret key and accepts only clients whose
public keys (``*.key``) are in its ``authorized_dir``, checked by a ZAP handler
(`zmq.auth.thread.ThreadAuthenticator`, one per context, each server socket with its own ZAP
domain). A connecting socket is the client: its own key pair plus the server's public key.
Key pairs are made by ``supportnode keys DIR --name NAME`` (``NAME.key`` public,
``NAME.key_secret`` both). `supportnode.bus` takes ``curve=CurveKeys(...)``.

The node's key folder (``node.curve_keys_dir``), which key each of its sockets uses:

    DIR/server.key_secret   the node's own key pair: server of the sockets it binds, its
                            identity on the sockets it connects
    DIR/scan_server.key     the scan driver's public key (the node connects for scans, its
                            default; a result socket that connects uses it as well)
    DIR/subscribers/*.key   clients that may subscribe to the results (planners, viewers)
    DIR/drivers/*.key       drivers that may publish scans to a node that binds its scan
                            socket (node.scan_bind: true)

Server keys and authorised client keys live apart: the folder's own keys authorise nobody, so
a driver's key pair can subscribe to results only when its public key is in subscribers/.
(The old layout kept the clients' ``*.key`` beside the node's own keys, which authorised the
node's and the driver's pairs as clients too; it is refused with a one-line error naming the
new one.) ``supportnode keys`` makes the pairs.
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import zmq

from supportnode.errors import BusError

__all__ = [
    "DRIVERS",
    "OWN_KEYS",
    "SUBSCRIBERS",
    "CurveKeys",
    "NodeKeys",
    "configure_curve",
    "node_keys",
    "release_curve",
]


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


def release_curve(context: zmq.Context, domain: str) -> None:
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


def configure_curve(sock: zmq.Socket, context: zmq.Context, curve: CurveKeys, bind: bool) -> str:
    """Configure CURVE on ``sock`` before it binds or connects: server when binding (ZAP
    checks the clients against ``curve.authorized_dir``), else client. Returns the server's ZAP
    domain (give it back with `release_curve` once the socket is closed), "" for a client."""
    if not zmq.has("curve"):
        raise BusError("CURVE requested but this libzmq was built without CURVE support")
    public, secret = _load_key(curve.key_file, need_secret=True)
    assert secret is not None  # _load_key raised otherwise
    try:
        if bind:
            _load_authorized(curve.authorized_dir)
            sock.setsockopt(zmq.CURVE_SERVER, 1)
            sock.setsockopt(zmq.CURVE_SECRETKEY, secret)
            domain = _auth_acquire(context, os.fspath(curve.authorized_dir))
            sock.setsockopt_string(zmq.ZAP_DOMAIN, domain)
            # Without this, libzmq accepts every CURVE client while no ZAP handler is
            # bound (e.g. while the shared authenticator restarts): fail closed instead.
            sock.setsockopt(zmq.ZAP_ENFORCE_DOMAIN, 1)
            return domain
        if not os.fspath(curve.server_key):
            raise BusError("CURVE client: no server_key given (the server's .key file)")
        server_public, _ = _load_key(curve.server_key, need_secret=False)
        sock.setsockopt(zmq.CURVE_PUBLICKEY, public)
        sock.setsockopt(zmq.CURVE_SECRETKEY, secret)
        sock.setsockopt(zmq.CURVE_SERVERKEY, server_public)
        return ""
    except zmq.ZMQError as err:
        raise BusError(f"{os.fspath(curve.key_file)}: invalid CURVE key ({err})") from err


SUBSCRIBERS = "subscribers"
DRIVERS = "drivers"
#: Files that belong in the folder's root.
OWN_KEYS = ("server.key_secret", "server.key", "scan_server.key")


@dataclass(frozen=True)
class NodeKeys:
    """CURVE keys of the node's two sockets."""

    results: CurveKeys
    scans: CurveKeys


def node_keys(folder: str, scan_bind: bool) -> NodeKeys:
    """The keys of a node whose key folder is ``folder`` (layout: module docstring); a
    one-line BusError for an empty setting or the old layout."""
    if not folder:
        raise BusError("node.curve_enabled is true but node.curve_keys_dir is empty")
    _refuse_old_layout(folder)
    secret = os.path.join(folder, "server.key_secret")
    driver = os.path.join(folder, "scan_server.key")
    results = CurveKeys(secret, os.path.join(folder, SUBSCRIBERS), driver)
    if scan_bind:
        return NodeKeys(results, CurveKeys(secret, authorized_dir=os.path.join(folder, DRIVERS)))
    return NodeKeys(results, CurveKeys(secret, server_key=driver))


def _refuse_old_layout(folder: str) -> None:
    try:
        loose = sorted(e for e in os.listdir(folder) if e.endswith(".key") and e not in OWN_KEYS)
    except OSError:
        return  # a missing folder: the key files' own errors name it
    if loose:
        raise BusError(
            f"{folder}: client keys ({', '.join(loose[:3])}{', ...' if len(loose) > 3 else ''})"
            f" in the key folder's root: move them to {SUBSCRIBERS}/ (may subscribe to "
            f"results) or {DRIVERS}/ (may publish scans); the root holds only "
            f"{', '.join(OWN_KEYS)}"
        )
