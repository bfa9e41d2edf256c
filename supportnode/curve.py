"""The node's CURVE key folder (``node.curve_keys_dir``): which key each socket uses.

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

import os
from dataclasses import dataclass

from supportnode.bus import BusError, CurveKeys

__all__ = ["DRIVERS", "OWN_KEYS", "SUBSCRIBERS", "NodeKeys", "node_keys"]

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
