"""Live view in Foxglove: our messages converted to Foxglove's schemas, served over its WebSocket
protocol or written to an MCAP file the Foxglove app opens directly.

- `supportnode.view.foxglove_bridge`: pure conversion (decoded messages in, foxglove messages out);
- `supportnode.view.sink`: foxglove channels per topic, the WebSocket server and the MCAP writer.

Both need the optional ``foxglove-sdk`` package (``pip install 'supportnode[view]'``); this module
does not import it, so that `require_foxglove` can say so in one line.
"""

from __future__ import annotations

from supportnode.errors import SupportNodeError

__all__ = ["INSTALL_HINT", "ViewError", "require_foxglove"]

INSTALL_HINT = "install with pip install 'supportnode[view]'"


class ViewError(SupportNodeError):
    """The live view cannot start (foxglove-sdk missing, port in use, bad output path)."""


def require_foxglove() -> None:
    """Raise ViewError (one line, with the install command) when foxglove-sdk is missing."""
    try:
        import foxglove
        import foxglove.channels
        import foxglove.messages  # noqa: F401
    except ImportError as err:
        raise ViewError(f"the live view needs foxglove-sdk: {INSTALL_HINT}") from err
