"""Where converted messages go: one foxglove channel per topic on a private foxglove Context,
and the two sinks of such a context, a WebSocket server (live) or an MCAP file (Foxglove opens it).

    ctx = foxglove.Context()
    server = serve(ctx, "127.0.0.1", 8765)        # or: writer = write_mcap(ctx, "out.mcap")
                                                  # (behind an Origin check: view.origins)
    channels = Channels(ctx)
    channels.log(bridge.convert(msg, topic), log_time_ns)

A private context (not the SDK's global one) keeps several views, and tests, apart.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import foxglove
import foxglove.channels

from supportnode.view import ViewError
from supportnode.view.foxglove_bridge import DIAGNOSTICS_SCHEMA, Item
from supportnode.view.origins import HIDDEN_PORTS, OriginRelay

__all__ = ["Channels", "ViewServer", "serve", "write_mcap"]


class Channels:
    """Creates each topic's channel on first use, typed by its first message (a foxglove
    message class -> its typed channel, e.g. SceneUpdate -> SceneUpdateChannel; a dict -> a
    JSON channel with `DIAGNOSTICS_SCHEMA`). A topic keeps its first type: later messages of
    another type on it are skipped and counted in ``mismatched``."""

    def __init__(self, context: foxglove.Context) -> None:
        self.context = context
        self._channels: dict[str, tuple[type, Any]] = {}
        self.logged = 0
        self.mismatched = 0

    def log(self, items: Iterable[Item], log_time: int) -> None:
        """Log ``items``; ``log_time``: ns since the epoch (receive or recorded time)."""
        for item in items:
            kind = type(item.message)
            entry = self._channels.get(item.topic)
            if entry is None:
                entry = self._channels[item.topic] = (kind, self._open(item.topic, kind))
            if entry[0] is not kind:
                self.mismatched += 1
                continue
            entry[1].log(item.message, log_time=log_time)
            self.logged += 1

    @property
    def topics(self) -> list[str]:
        """Topics with a channel, in creation order."""
        return list(self._channels)

    def _open(self, topic: str, kind: type) -> Any:
        if kind is dict:
            return foxglove.Channel(topic, schema=DIAGNOSTICS_SCHEMA, context=self.context)
        cls = getattr(foxglove.channels, f"{kind.__name__}Channel")
        return cls(topic, context=self.context)

    def close(self) -> None:
        """Close every channel (unadvertises them from a server)."""
        for _, channel in self._channels.values():
            channel.close()
        self._channels.clear()


class ViewServer:
    """The Foxglove WebSocket server behind its origin check (`supportnode.view.origins`):
    ``port`` is where viewers connect; ``exposed`` says the Foxglove server had to take a port
    that browsers can reach directly (every hidden port in use)."""

    def __init__(self, server: Any, relay: OriginRelay, exposed: bool) -> None:
        self.server, self.relay, self.exposed = server, relay, exposed
        self.port = relay.port

    def app_url(self, host: str) -> str:
        """The Foxglove web app's link that opens this server."""
        from urllib.parse import quote

        return f"https://app.foxglove.dev?ds=foxglove-websocket&ds.url={quote(self.ws_url(host), safe='')}"

    def ws_url(self, host: str) -> str:
        return f"ws://{host}:{self.port}"

    def stop(self) -> None:
        self.relay.close()
        self.server.stop()


def serve(
    context: foxglove.Context,
    host: str,
    port: int,
    allow_origins: Sequence[str] = (),
    report: Callable[[str], None] | None = None,
) -> ViewServer:
    """A Foxglove WebSocket server for ``context``, reached on ``host:port`` (port 0: a free
    one; the actual port is ``.port``) through the origin check: allowed origins as
    `origin_allowed` says, plus ``allow_origins``; ``report`` gets a line per refused origin.
    Raises ViewError when it cannot listen."""
    server, exposed = None, False
    for hidden in (*HIDDEN_PORTS, 0):
        try:
            server = foxglove.start_server(
                name="supportnode", host="127.0.0.1", port=hidden, context=context
            )
            exposed = hidden == 0
            break
        except RuntimeError as err:  # the SDK's FoxgloveError, e.g. address in use
            if hidden == 0:
                raise ViewError(f"cannot start the Foxglove server: {err}") from err
    assert server is not None
    try:
        relay = OriginRelay(host, port, ("127.0.0.1", server.port), allow_origins, report)
    except OSError as err:
        server.stop()
        raise ViewError(f"cannot serve on {host}:{port}: {err.strerror or err}") from err
    return ViewServer(server, relay, exposed)


def write_mcap(context: foxglove.Context, path: str | os.PathLike[str]) -> Any:
    """An MCAP writer recording every channel of ``context`` to ``path`` (overwritten; zstd
    chunks, indexed). Close it (or use ``with``) to finish the file."""
    try:
        return foxglove.open_mcap(os.fspath(path), allow_overwrite=True, context=context)
    except (RuntimeError, OSError) as err:
        raise ViewError(f"{os.fspath(path)}: cannot write ({err})") from err
