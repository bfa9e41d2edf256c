"""supportnode: support surfaces and the objects standing on them, offline and as a ZeroMQ node."""

__version__ = "0.1.0"
