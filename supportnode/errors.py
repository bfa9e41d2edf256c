"""Exception hierarchy. The library raises; only the CLI prints and exits.

Every message is one line that says what went wrong and where (file, line, key, topic).
"""


class SupportNodeError(Exception):
    """Root of every error supportnode raises on bad input or configuration."""


class CloudFormatError(SupportNodeError):
    """A point-cloud file cannot be read or written (missing, unknown format, truncated, empty)."""


class ConfigError(SupportNodeError):
    """A configuration file or override is invalid (unknown key, wrong type, out of range)."""


class SceneError(SupportNodeError):
    """A simulator scene description is invalid."""


class ProtocolError(SupportNodeError):
    """A wire message cannot be decoded or fails validation.

    reason: the short reject reason a receiver counts it under (``malformed``, ``version``,
    ``nonfinite``, ``bad_gravity``, ...: docs/protocol.md section 9)."""

    def __init__(self, message: str, reason: str = "malformed") -> None:
        super().__init__(message)
        self.reason = reason

    def __reduce__(self):  # keeps the reason through pickling (the detection worker)
        return (type(self), (str(self), self.reason))


class BusError(SupportNodeError):
    """A socket cannot bind or connect to an endpoint (bad address, address in use), or its
    CURVE keys cannot be used (missing or unreadable key file)."""


class AlignmentError(SupportNodeError):
    """Gravity alignment cannot be estimated from the cloud (e.g. no horizontal surface in view)."""


class InputError(SupportNodeError):
    """Numeric input that geometry cannot use (wrong shape, non-finite values, no points)."""
