"""How a configuration key is declared: a dataclass field with its help, unit and limits."""

from __future__ import annotations

from dataclasses import field
from typing import Any


def param(default: Any, help: str, unit: str = "", **limits: Any) -> Any:
    """A dataclass field with documentation and limits for the configuration loader."""
    meta = {"help": help, "unit": unit, **limits}
    if isinstance(default, (list, tuple)):
        return field(default_factory=lambda: tuple(default), metadata=meta)
    return field(default=default, metadata=meta)
