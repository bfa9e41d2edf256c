"""Typed parameters: one frozen dataclass per stage, under one root `DetectParams`.

Each field carries metadata used by `supportnode.config` to document, parse and range-check it:
``unit`` (SI unit or ``""``), ``help`` (one line), and optional ``min`` / ``max`` (inclusive) or
``choices``. Defaults here are the built-in defaults (lowest precedence: defaults < YAML < --set).

- `detection`: the detection's stages (`SurfaceParams`, `ObjectParams`, `FreeSpaceParams`,
  `GravityParams`, `SafeParams`);
- `node`: the ZeroMQ node and its map (`NodeParams`, `MapParams`);
- `base`: `param`, how a key is declared.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from supportnode.params.base import param
from supportnode.params.detection import (
    FreeSpaceParams,
    GravityParams,
    ObjectParams,
    SafeParams,
    SurfaceParams,
)
from supportnode.params.node import MapParams, NodeParams

__all__ = [
    "DetectParams",
    "FreeSpaceParams",
    "GravityParams",
    "MapParams",
    "NodeParams",
    "ObjectParams",
    "SafeParams",
    "SurfaceParams",
    "param",
]


@dataclass(frozen=True)
class DetectParams:
    """Everything `supportnode detect` and the node's detection stage use."""

    surfaces: SurfaceParams = field(default_factory=SurfaceParams)
    objects: ObjectParams = field(default_factory=ObjectParams)
    freespace: FreeSpaceParams = field(default_factory=FreeSpaceParams)
    gravity: GravityParams = field(default_factory=GravityParams)
    safe: SafeParams = field(default_factory=SafeParams)
    node: NodeParams = field(default_factory=NodeParams)
