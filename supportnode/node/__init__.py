"""The node: `core` (ingest, detect), `node` (threads and sockets around it), `tracking` (stable ids)."""

__all__ = ["Node", "NodeOutput"]


def __getattr__(name: str):  # lazy: `node.map` users do not pay for ZeroMQ and the pipeline
    if name in __all__:
        from supportnode.node import node as _node

        return getattr(_node, name)
    raise AttributeError(f"module 'supportnode.node' has no attribute {name!r}")
