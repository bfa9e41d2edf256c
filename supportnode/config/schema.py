"""The configuration's schema: its keys, their types, ranges and help, and the keys that went.

The keys themselves are declared in `supportnode.params` (root `DetectParams`): a section is a
field whose type is a dataclass, a key is any other field. Each key's metadata (``help``,
``unit``, ``min``/``max`` inclusive, ``choices``) documents it in the generated ``default.yaml``
and range-checks it on loading. This module derives, once per root dataclass, the tree of
`Section` and `Leaf` that loading and dumping walk. Adding a section is adding a dataclass-typed
field to the root.

Supported key types: ``bool``, ``int``, ``float``, ``str`` and fixed-length
``tuple[float, ...]`` (written as a YAML list of that length).
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass
from typing import Any

# Keys that existed and went: full dotted key -> what to do instead. Reading one is an error
# that says so (never an "unknown key" guess, never silently ignored).
_NOTHING_TO_SET = "detection now keeps pace, nothing to set"
REMOVED_KEYS: dict[str, str] = {
    "node.pipeline": "removed in 0.2: the node always merges in its receiving thread and "
    "detects the latest scan in a second one; " + _NOTHING_TO_SET,
    "node.detect_process": "removed in 0.2: "
    + _NOTHING_TO_SET
    + " (set node.threads to bound the kernels' threads)",
    "node.surfaces_first": "removed in 0.2: "
    + _NOTHING_TO_SET
    + " (a detection's surfaces go out first, then its obstacles)",
    "node.defer_clear": "removed in 0.2: "
    + _NOTHING_TO_SET
    + " (each scan's clearing runs in its merge)",
    "node.queue": "removed in 0.2: the node keeps the latest scan, " + _NOTHING_TO_SET,
    # read by nothing: the point normals that surfaces use have their own neighbour counts
    "normals": "removed in 0.2: use surfaces.normal_filter_k and surfaces.clutter_normal_k",
    "objects.convex_band_sigma": "removed in 0.2: the band over a surface is the surface's "
    "measured noise band; use surfaces.band_sigmas and surfaces.band_min",
    "objects.convex_crease_curvature": "removed in 0.2: the convex method judges creases "
    "between smooth faces; " + _NOTHING_TO_SET,
}

# Keys renamed for what they are (four keys were all called voxel_size): old -> new dotted key.
# Each is in REMOVED_KEYS too: "key 'surfaces.voxel_size' was renamed in 0.2: use '...'".
RENAMED_KEYS: dict[str, str] = {
    "surfaces.voxel_size": "surfaces.plane_voxel",
    "objects.voxel_size": "objects.cluster_cell",
    "gravity.voxel_size": "gravity.downsample_voxel",
}
REMOVED_KEYS.update({old: f"renamed in 0.2: use '{new}'" for old, new in RENAMED_KEYS.items()})


@dataclass(frozen=True)
class Leaf:
    """One key: its Python type, metadata and, for tuples, the required length."""

    name: str
    kind: type  # bool, int, float, str or tuple (of floats)
    length: int  # tuples only
    help: str
    unit: str
    min: float | None
    max: float | None
    choices: tuple[Any, ...] | None


@dataclass(frozen=True)
class Section:
    """One dataclass: its keys and subsections, in declaration order."""

    cls: type
    doc: str
    fields: dict[str, Leaf | Section]


_SCHEMAS: dict[type, Section] = {}


def schema_of(cls: type) -> Section:
    """The schema of dataclass ``cls``; TypeError for a field type the loader cannot parse."""
    if cls not in _SCHEMAS:
        _SCHEMAS[cls] = _make_schema(cls)
    return _SCHEMAS[cls]


def _make_schema(cls: type) -> Section:
    """Derive the schema of ``cls`` from its type hints, defaults and field metadata."""
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise TypeError(f"{cls!r} is not a dataclass type")
    hints = typing.get_type_hints(cls)
    defaults = cls()
    out: dict[str, Leaf | Section] = {}
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            out[f.name] = schema_of(hint)
            continue
        meta = f.metadata
        kind: type
        length = 0
        if hint in (bool, int, float, str):
            kind = hint
        elif typing.get_origin(hint) is tuple and _float_tuple_args(typing.get_args(hint)):
            kind = tuple
            length = len(getattr(defaults, f.name))
            args = typing.get_args(hint)
            if args[-1] is not Ellipsis and len(args) != length:
                raise TypeError(f"{cls.__name__}.{f.name}: default length differs from {hint}")
        else:
            raise TypeError(f"{cls.__name__}.{f.name}: unsupported configuration type {hint}")
        choices = meta.get("choices")
        out[f.name] = Leaf(
            name=f.name,
            kind=kind,
            length=length,
            help=str(meta.get("help", "")),
            unit=str(meta.get("unit", "")),
            min=meta.get("min"),
            max=meta.get("max"),
            choices=tuple(choices) if choices is not None else None,
        )
    doc = (cls.__doc__ or "").strip().splitlines()
    return Section(cls=cls, doc=doc[0] if doc else "", fields=out)


def _float_tuple_args(args: tuple[Any, ...]) -> bool:
    """True for the arguments of ``tuple[float, ...]`` or ``tuple[float, float, ...]``."""
    if len(args) == 2 and args[1] is Ellipsis:
        return args[0] is float
    return len(args) > 0 and all(a is float for a in args)


def num(value: float) -> str:
    """A limit as people write it: 0.001, 10, 0."""
    return f"{value:g}"
