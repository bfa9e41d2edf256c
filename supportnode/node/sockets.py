"""The node's two sockets: scans in (the subscriber), results out (the publisher)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import zmq

from supportnode import bus
from supportnode.curve import NodeKeys, node_keys
from supportnode.params import NodeParams

__all__ = ["NodeSockets"]


class NodeSockets:
    """Creates, reports on and closes the node's sockets (``node.*`` endpoints, CURVE).

    check: the subscriber's check of each message as it comes off the socket (decode and
    admit: only usable scans take the newest-scan place). report: (socket name, line) of a
    failed handshake (`supportnode.handshake`).
    """

    def __init__(
        self,
        cfg: NodeParams,
        context: zmq.Context | None,
        check: Callable[[Any], Any],
        report: Callable[[str, str], None],
    ) -> None:
        self.cfg = cfg
        self._context = context
        self._check = check
        self._report = report
        self.sub: bus.Subscriber | None = None
        self.pub: bus.Publisher | None = None

    def open(self) -> bool:
        """Create both sockets; False when they are open already."""
        if self.sub is not None:
            return False
        cfg = self.cfg
        curve = self._curve_keys()
        pub = bus.Publisher(
            cfg.pub_endpoint,
            bind=cfg.pub_bind,
            context=self._context,
            hwm=10,
            curve=None if curve is None else curve.results,
            watch=lambda line: self._report("results", line),
        )
        try:
            self.sub = bus.Subscriber(
                cfg.scan_endpoint,
                cfg.scan_topic,
                bind=cfg.scan_bind,
                keep_newest=1,
                context=self._context,
                max_message_bytes=cfg.max_message_bytes,
                curve=None if curve is None else curve.scans,
                check=self._check,
                watch=lambda line: self._report("scans", line),
            )
        except BaseException:
            pub.close()
            raise
        self.pub = pub
        return True

    def _curve_keys(self) -> NodeKeys | None:
        """CURVE keys of both sockets from ``curve_keys_dir`` when ``curve_enabled``."""
        if not self.cfg.curve_enabled:
            return None
        return node_keys(self.cfg.curve_keys_dir, self.cfg.scan_bind)

    def handshake_counters(self) -> dict[str, int]:
        """Failed handshakes of the node's sockets, by socket and kind."""
        out = {}
        for name, sock in (("scans", self.sub), ("results", self.pub)):
            if sock is not None:
                for kind, n in sock.handshake_failures().items():
                    out[f"handshake_failures_{name}_{kind}"] = n
        return out

    @property
    def pub_endpoint(self) -> str:
        """Resolved result endpoint (the real port after binding ``tcp://host:*``)."""
        return self.pub.endpoint if self.pub is not None else self.cfg.pub_endpoint

    @property
    def scan_endpoint(self) -> str:
        """Resolved scan endpoint."""
        return self.sub.endpoint if self.sub is not None else self.cfg.scan_endpoint

    def close(self) -> None:
        """Close both sockets (idempotent)."""
        for s in (self.sub, self.pub):
            if s is not None:
                s.close()
        self.sub = self.pub = None
