"""Typed, strict configuration: built-in defaults < YAML file < ``--set key=value`` overrides.

The schema is the tree of frozen dataclasses in `supportnode.params` (root `DetectParams`): a section
is a field whose type is a dataclass, a key is any other field. Each key's metadata (``help``,
``unit``, ``min``/``max`` inclusive, ``choices``) documents it in the generated ``default.yaml`` and
range-checks it on loading. Adding a section is adding a dataclass-typed field to the root.

Every problem raises `ConfigError` with one line naming where it is (``file:line`` or ``--set ...``)
and which key, e.g. ``config/my.yaml:7: unknown key 'surfaces.voxl_size' (did you mean
'voxel_size'?)``. Unknown keys are never ignored. YAML is composed into nodes (not ``safe_load``)
so that every value keeps its line number.

Supported key types: ``bool``, ``int``, ``float`` (an integer is accepted), ``str`` and fixed-length
``tuple[float, ...]`` (written as a YAML list of that length). A boolean is never taken for a number
(YAML ``yes`` is not 1). Numbers in exponent form without a dot (``1e-3``), which PyYAML's YAML 1.1
rules read as text, are read as numbers when written unquoted.

Run ``python -m supportnode.config > config/default.yaml`` to regenerate the default file.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import os
import re
import textwrap
import typing
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TypeAlias, TypeVar, overload

import yaml

from supportnode.errors import ConfigError
from supportnode.params import DetectParams
from supportnode.yamlnodes import Constructor, compose, line_of, read_text, short_tag

__all__ = [
    "config_to_dict",
    "dump_default_yaml",
    "dump_yaml",
    "load_config",
    "parse_override",
]

T = TypeVar("T")
PathArg: TypeAlias = "str | os.PathLike[str] | None"

_NULL_TAG = "tag:yaml.org,2002:null"
_STR_TAG = "tag:yaml.org,2002:str"
_BOOL_TAG = "tag:yaml.org,2002:bool"
_MERGE_TAG = "tag:yaml.org,2002:merge"
_MAP_TAG = "tag:yaml.org,2002:map"
_SEQ_TAG = "tag:yaml.org,2002:seq"
_PLAIN_TAGS = frozenset(
    f"tag:yaml.org,2002:{name}" for name in ("null", "bool", "int", "float", "str", "map", "seq")
)
# Plain scalars that are numbers to a reader but text to YAML 1.1 (e.g. "1e-3", "1.0e3").
_EXP_NUMBER = re.compile(r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+")
_KEY_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_COMMENT_WIDTH = 100

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


# --------------------------------------------------------------------------------------------
# Schema: derived once per root dataclass from the type hints and field metadata.


@dataclass(frozen=True)
class _Leaf:
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
class _Section:
    """One dataclass: its keys and subsections, in declaration order."""

    cls: type
    doc: str
    fields: dict[str, _Leaf | _Section]


_SCHEMAS: dict[type, _Section] = {}


def _schema(cls: type) -> _Section:
    """The schema of dataclass ``cls``; raises TypeError for a field type the loader cannot parse."""
    if cls not in _SCHEMAS:
        _SCHEMAS[cls] = _make_schema(cls)
    return _SCHEMAS[cls]


def _make_schema(cls: type) -> _Section:
    """Derive the schema of ``cls`` from its type hints, defaults and field metadata."""
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise TypeError(f"{cls!r} is not a dataclass type")
    hints = typing.get_type_hints(cls)
    defaults = cls()
    out: dict[str, _Leaf | _Section] = {}
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            out[f.name] = _schema(hint)
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
        out[f.name] = _Leaf(
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
    return _Section(cls=cls, doc=doc[0] if doc else "", fields=out)


def _float_tuple_args(args: tuple[Any, ...]) -> bool:
    """True for the arguments of ``tuple[float, ...]`` or ``tuple[float, float, ...]``."""
    if len(args) == 2 and args[1] is Ellipsis:
        return args[0] is float
    return len(args) > 0 and all(a is float for a in args)


# --------------------------------------------------------------------------------------------
# Checking YAML nodes against the schema.


@dataclass(frozen=True)
class _Source:
    """Where values come from: a file (errors give file:line) or one ``--set`` (errors give it)."""

    label: str
    is_file: bool

    def fail(self, node: yaml.Node | None, message: str) -> ConfigError:
        """A ConfigError prefixed with this source (and the node's line for files)."""
        if self.is_file and line_of(node):
            return ConfigError(f"{self.label}:{line_of(node)}: {message}")
        return ConfigError(f"{self.label}: {message}")


class _Checker:
    """Validates composed YAML nodes against a schema, producing nested dicts of checked values."""

    def __init__(self, source: _Source) -> None:
        self.source = source
        self._values = Constructor()

    def close(self) -> None:
        """Release the PyYAML constructor."""
        self._values.close()

    def construct(self, node: yaml.Node, path: str) -> Any:
        """The plain Python value of a node (as ``yaml.safe_load`` would give it).

        Tags the safe loader cannot build (``!!python/...``, ``!foo``, ``!!int abc``) raise a
        ConfigError naming ``path``.
        """
        where = f"{path}: " if path else ""

        def fail(n: yaml.Node, problem: str) -> ConfigError:
            shown = f"cannot read {n.value!r} tagged {short_tag(n.tag)} ({problem})"
            return self.source.fail(n, where + shown)

        return self._values.checked(node, fail)

    def section(self, schema: _Section, node: yaml.Node, path: str) -> dict[str, Any]:
        """Check a mapping node as section ``schema`` at dotted ``path`` ("" for the root)."""
        if isinstance(node, yaml.ScalarNode) and node.tag == _NULL_TAG:
            return {}  # "surfaces:" with every key commented out: an empty section
        if not isinstance(node, yaml.MappingNode) or node.tag != _MAP_TAG:
            what = f"{path}: expected a section" if path else "expected sections at the top level"
            raise self.source.fail(node, f"{what} (a mapping of keys), got {self.describe(node)}")
        out: dict[str, Any] = {}
        first_line: dict[str, int] = {}
        for key_node, value_node in node.value:
            if key_node.tag == _MERGE_TAG:
                raise self.source.fail(key_node, "YAML merge keys ('<<') are not supported")
            if not isinstance(key_node, yaml.ScalarNode):
                raise self.source.fail(
                    key_node, f"keys must be plain names, got {self.describe(key_node)}"
                )
            key = str(key_node.value)
            full = f"{path}.{key}" if path else key
            if key in first_line:
                raise self.source.fail(
                    key_node, f"duplicate key '{full}' (first given at line {first_line[key]})"
                )
            first_line[key] = key_node.start_mark.line + 1 if key_node.start_mark else 0
            field = self.lookup(schema, key, full, key_node)
            if isinstance(field, _Section):
                out[key] = self.section(field, value_node, full)
            else:
                out[key] = self.leaf(field, value_node, full)
        return out

    def lookup(
        self, schema: _Section, key: str, full: str, node: yaml.Node | None
    ) -> _Leaf | _Section:
        """The field ``key`` of ``schema``, or an 'unknown key' error with a suggestion."""
        if key in schema.fields:
            return schema.fields[key]
        if full in REMOVED_KEYS:
            raise self.source.fail(node, f"key '{full}' was {REMOVED_KEYS[full]}")
        known = list(schema.fields)
        close = difflib.get_close_matches(key, known, n=1)
        hint = f"did you mean '{close[0]}'?" if close else "known keys: " + ", ".join(known)
        raise self.source.fail(node, f"unknown key '{full}' ({hint})")

    def leaf(self, leaf: _Leaf, node: yaml.Node, path: str) -> Any:
        """Check one key's value node; returns the value as the dataclass field holds it."""
        if leaf.kind is tuple:
            if (
                not isinstance(node, yaml.SequenceNode)
                or node.tag != _SEQ_TAG
                or len(node.value) != leaf.length
            ):
                raise self.source.fail(
                    node,
                    f"{path}: expected a list of {leaf.length} numbers, got {self.describe(node)}",
                )
            return tuple(
                self.number(leaf, float, item, f"{path}[{i}]") for i, item in enumerate(node.value)
            )
        if leaf.kind is bool:
            value = self.scalar(node, path)
            if not isinstance(value, bool):
                raise self.source.fail(
                    node, f"{path}: expected true or false, got {self.describe(node)}"
                )
            return value
        if leaf.kind is str:
            value = self.scalar(node, path)
            if not isinstance(value, str):
                raise self.source.fail(
                    node, f"{path}: expected a string, got {self.describe(node)}"
                )
            self.check_choices(leaf, value, node, path)
            return value
        return self.number(leaf, leaf.kind, node, path)

    def number(self, leaf: _Leaf, kind: type, node: yaml.Node, path: str) -> int | float:
        """Check an int or float scalar node against the type, the limits and the choices."""
        value: Any = self.scalar(node, path)
        if (
            kind is float
            and isinstance(value, str)
            and isinstance(node, yaml.ScalarNode)
            and node.style is None
            and _EXP_NUMBER.fullmatch(value)
        ):
            value = float(value)
        ok = isinstance(value, int) if kind is int else isinstance(value, (int, float))
        if isinstance(value, bool) or not ok:
            expected = "an integer" if kind is int else "a number"
            raise self.source.fail(node, f"{path}: expected {expected}, got {self.describe(node)}")
        if kind is float:
            value = float(value)
            if not math.isfinite(value):
                raise self.source.fail(node, f"{path}: expected a finite number, got {value}")
        number: int | float = value
        self.check_choices(leaf, number, node, path)
        unit = f" {leaf.unit}" if leaf.unit else ""
        if leaf.min is not None and number < leaf.min:
            raise self.source.fail(
                node, f"{path}: {number}{unit} is below the minimum {_num(leaf.min)}{unit}"
            )
        if leaf.max is not None and number > leaf.max:
            raise self.source.fail(
                node, f"{path}: {number}{unit} is above the maximum {_num(leaf.max)}{unit}"
            )
        return number

    def check_choices(self, leaf: _Leaf, value: Any, node: yaml.Node, path: str) -> None:
        """Raise unless ``value`` is one of the key's choices (when it has any)."""
        if leaf.choices is not None and value not in leaf.choices:
            shown = f"'{value}'" if isinstance(value, str) else str(value)
            options = ", ".join(str(c) for c in leaf.choices)
            raise self.source.fail(node, f"{path}: {shown} is not one of {options}")

    def scalar(self, node: yaml.Node, path: str) -> Any:
        """The value of a scalar node; a list or mapping gives a sentinel the type checks reject."""
        if not isinstance(node, yaml.ScalarNode):
            return _NOT_SCALAR
        return self.construct(node, path)

    def describe(self, node: yaml.Node) -> str:
        """How a wrong value is shown in an error: 'two', 2.5, true, null, a list, a mapping."""
        tagged = ""
        if node.tag == "tag:yaml.org,2002:timestamp":
            return f"{node.value} (a date)"
        if node.tag not in _PLAIN_TAGS:
            tagged = f" tagged {short_tag(node.tag)}"
        if isinstance(node, yaml.MappingNode):
            return f"a mapping{tagged}"
        if isinstance(node, yaml.SequenceNode):
            return f"a list of {len(node.value)} items{tagged}"
        if tagged:
            return f"{node.value!r}{tagged}"
        if node.tag == _NULL_TAG:
            return "nothing (null)"
        if node.tag == _STR_TAG:
            return repr(str(node.value))
        if node.tag == _BOOL_TAG:
            return f"{node.value} (a boolean)"
        return str(node.value)


_NOT_SCALAR = object()


# --------------------------------------------------------------------------------------------
# Public API.


def parse_override(text: str) -> tuple[list[str], Any]:
    """Split a ``--set`` override ``"a.b=value"`` into its key path and its YAML value.

    The value is parsed as YAML (``objects.k=50`` gives 50, ``surfaces.voxel_size=[0.1,0.1,0.07]``
    a list, ``surfaces.method=seed`` the string); type and range checks happen in `load_config`.
    Raises `ConfigError` naming the override when it has no ``=``, a malformed key or bad YAML.
    """
    path, node = _compose_override(text)
    checker = _Checker(_Source(f"--set {text}", is_file=False))
    try:
        return path, checker.construct(node, ".".join(path))
    finally:
        checker.close()


def _compose_override(text: str) -> tuple[list[str], yaml.Node]:
    """The key path and the composed YAML value node of one override."""
    source = _Source(f"--set {text}", is_file=False)
    key, sep, value_text = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise source.fail(None, "expected key=value, e.g. --set surfaces.method=seed")
    path = key.split(".")
    if not all(_KEY_NAME.fullmatch(part) for part in path):
        raise source.fail(None, f"malformed key '{key}' (expected names joined by dots)")
    try:
        node = yaml.compose(value_text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as err:
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise source.fail(None, f"cannot parse the value as YAML: {problem}") from err
    if node is None:  # "key=" (nothing after "=")
        node = yaml.ScalarNode(_NULL_TAG, "")
    return path, node


@overload
def load_config(path: PathArg = None, overrides: Sequence[str] = ()) -> DetectParams: ...
@overload
def load_config(path: PathArg, overrides: Sequence[str], root_type: type[T]) -> T: ...
@overload
def load_config(
    path: PathArg = None, overrides: Sequence[str] = (), *, root_type: type[T]
) -> T: ...
def load_config(
    path: PathArg = None, overrides: Sequence[str] = (), root_type: type[Any] = DetectParams
) -> Any:
    """Build the configuration: built-in defaults < YAML file ``path`` < ``overrides``.

    ``path`` may be None (defaults only); an empty file also means all defaults. ``overrides`` are
    ``--set`` strings such as ``"surfaces.voxel_size=[0.1,0.1,0.07]"`` or ``"objects.k=50"``,
    applied in order (a later one wins). ``root_type`` is the root dataclass (default
    `DetectParams`). Raises `ConfigError` with one line naming file:line (or the override) and key.
    """
    schema = _schema(root_type)
    values: dict[str, Any] = {}
    if path is not None:
        values = _load_file(schema, os.fspath(path))
    for text in overrides:
        key_path, node = _compose_override(text)
        checker = _Checker(_Source(f"--set {text}", is_file=False))
        try:
            _merge(values, _check_override(checker, schema, key_path, node))
        finally:
            checker.close()
    return _build(root_type(), schema, values)


def _load_file(schema: _Section, path: str) -> dict[str, Any]:
    """Read, compose and check one YAML file; returns its checked values as nested dicts."""
    source = _Source(path, is_file=True)
    node = compose(read_text(path, ConfigError), path, ConfigError)
    if node is None or (isinstance(node, yaml.ScalarNode) and node.tag == _NULL_TAG):
        return {}  # empty file (or only comments): all defaults
    checker = _Checker(source)
    try:
        return checker.section(schema, node, "")
    finally:
        checker.close()


def _check_override(
    checker: _Checker, schema: _Section, key_path: list[str], node: yaml.Node
) -> dict[str, Any]:
    """Check one override's value at ``key_path``; returns it nested as ``{a: {b: value}}``."""
    field: _Leaf | _Section = schema
    for i, key in enumerate(key_path):
        full = ".".join(key_path[: i + 1])
        if not isinstance(field, _Section):
            parent = ".".join(key_path[:i])
            raise checker.source.fail(None, f"unknown key '{full}' ('{parent}' is not a section)")
        field = checker.lookup(field, key, full, None)
    full = ".".join(key_path)
    value: Any = (
        checker.section(field, node, full)
        if isinstance(field, _Section)
        else checker.leaf(field, node, full)
    )
    nested: dict[str, Any] = {key_path[-1]: value}
    for key in reversed(key_path[:-1]):
        nested = {key: nested}
    return nested


def _merge(into: dict[str, Any], new: dict[str, Any]) -> None:
    """Deep-merge nested dict ``new`` into ``into`` (values of ``new`` win)."""
    for key, value in new.items():
        if isinstance(value, dict) and isinstance(into.get(key), dict):
            _merge(into[key], value)
        else:
            into[key] = value


def _build(default: Any, schema: _Section, values: dict[str, Any]) -> Any:
    """``default`` with the checked ``values`` (nested dicts for sections) replaced in."""
    changes: dict[str, Any] = {}
    for key, value in values.items():
        field = schema.fields[key]
        if isinstance(field, _Section):
            changes[key] = _build(getattr(default, key), field, value)
        else:
            changes[key] = value
    return dataclasses.replace(default, **changes)


def config_to_dict(cfg: Any) -> dict[str, Any]:
    """The configuration as plain nested dicts (tuples become lists), ready for JSON or YAML."""
    if not (dataclasses.is_dataclass(cfg) and not isinstance(cfg, type)):
        raise TypeError(f"expected a configuration dataclass instance, got {type(cfg).__name__}")
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            out[f.name] = config_to_dict(value)
        elif isinstance(value, (tuple, list)):
            out[f.name] = list(value)
        else:
            out[f.name] = value
    return out


# --------------------------------------------------------------------------------------------
# Writing YAML.


def _yaml_scalar(value: Any) -> str:
    """One scalar as YAML text that PyYAML (YAML 1.1) reads back to the same value and type."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        text = repr(value)
        if "." not in text and "e" in text:  # 1e-05 -> 1.0e-05, a float to YAML 1.1 too
            text = text.replace("e", ".0e", 1)
        return text
    if isinstance(value, str):
        plain = re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-./]*", value) is not None
        if plain and yaml.safe_load(value) == value:
            return value
        # A double-quoted YAML scalar; characters beyond the BMP as \U escapes (JSON would
        # write surrogate pairs, which YAML reads back as two characters).
        quoted = json.dumps(value, ensure_ascii=False)
        return "".join(
            f"\\U{ord(ch):08x}" if ord(ch) > 0xFFFF or not (ch.isprintable() or ch in '\\"') else ch
            for ch in quoted
        )
    raise TypeError(f"cannot write {type(value).__name__} {value!r} as a configuration scalar")


def _num(value: float) -> str:
    """A limit as people write it: 0.001, 10, 0."""
    return f"{value:g}"


def _yaml_value(value: Any) -> str:
    """A key's value as YAML text: a scalar or a flow list of scalars."""
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_yaml_scalar(v) for v in value) + "]"
    return _yaml_scalar(value)


def _describe_limits(leaf: _Leaf) -> str:
    """The comment line giving a key's type, unit and range or choices."""
    unit = f"unit: {leaf.unit}" if leaf.unit else "unitless"
    if leaf.kind is bool:
        return "true or false"
    if leaf.choices is not None:
        kind = {str: "string", int: "integer", float: "number"}[leaf.kind]
        return f"{kind}, one of: " + ", ".join(str(c) for c in leaf.choices)
    if leaf.kind is str:
        return "string"
    if leaf.min is not None and leaf.max is not None:
        limits = f"range: [{_num(leaf.min)}, {_num(leaf.max)}]"
    elif leaf.min is not None:
        limits = f"range: >= {_num(leaf.min)}"
    elif leaf.max is not None:
        limits = f"range: <= {_num(leaf.max)}"
    else:
        limits = "range: any"
    if leaf.kind is tuple:
        each = f"each in {limits.removeprefix('range: ')}" if "any" not in limits else "any values"
        return f"list of {leaf.length} numbers, {unit}, {each}"
    kind = "integer" if leaf.kind is int else "number"
    return f"{kind}, {unit}, {limits}" if leaf.kind is float else f"{kind}, {limits}"


def _comment(text: str, indent: str) -> list[str]:
    """``text`` as wrapped ``#`` comment lines at ``indent``."""
    width = _COMMENT_WIDTH - len(indent) - 2
    return [f"{indent}# {line}" for line in textwrap.wrap(text, width=width)]


def _dump_section(cfg: Any, schema: _Section, indent: str, comments: bool) -> list[str]:
    """The YAML lines of one section instance ``cfg``."""
    lines: list[str] = []
    for name, field in schema.fields.items():
        value = getattr(cfg, name)
        if isinstance(field, _Section):
            if comments and lines:
                lines.append("")
            if comments and field.doc:
                lines += _comment(field.doc, indent)
            lines.append(f"{indent}{name}:")
            lines += _dump_section(value, field, indent + "  ", comments)
            continue
        if comments:
            lines += _comment(field.help, indent) if field.help else []
            lines += _comment(f"({_describe_limits(field)})", indent)
        lines.append(f"{indent}{name}: {_yaml_value(value)}")
    return lines


def dump_yaml(cfg: Any, *, comments: bool = True) -> str:
    """The configuration ``cfg`` (a root dataclass instance) as YAML text `load_config` reads back.

    With ``comments``, every key is preceded by its meaning, unit and range or choices.
    """
    lines = _dump_section(cfg, _schema(type(cfg)), "", comments)
    return "\n".join(lines) + "\n"


def dump_default_yaml(root_type: type[Any] = DetectParams) -> str:
    """The text of ``config/default.yaml``: every key with its default and a comment."""
    header = [
        "# supportnode configuration: every key with its built-in default.",
        "# Generated from supportnode/params.py: python -m supportnode.config > config/default.yaml",
        "# (do not edit by hand; tests/test_config.py checks that this file is up to date).",
        "# Precedence: built-in defaults < YAML file < --set key=value. A config file needs only",
        "# the keys it changes; unknown keys are errors.",
        "",
    ]
    return "\n".join(header) + "\n" + dump_yaml(root_type(), comments=True)


if __name__ == "__main__":
    print(dump_default_yaml(), end="")
