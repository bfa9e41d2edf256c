"""Loading the configuration: built-in defaults < YAML file < ``--set key=value`` overrides.

Every problem raises `ConfigError` with one line naming where it is (``file:line`` or ``--set ...``)
and which key, e.g. ``config/my.yaml:7: unknown key 'surfaces.plane_voxl' (did you mean
'plane_voxel'?)``. Unknown keys are never ignored; a key that was removed or renamed is an error
naming what replaces it (`supportnode.config.schema.REMOVED_KEYS`). YAML is composed into nodes
(not ``safe_load``) so that every value keeps its line number.

A boolean is never taken for a number (YAML ``yes`` is not 1); an integer is accepted for a
``float`` key. Numbers in exponent form without a dot (``1e-3``), which PyYAML's YAML 1.1 rules
read as text, are read as numbers when written unquoted.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TypeAlias, TypeVar, overload

import yaml

from supportnode.config.schema import REMOVED_KEYS, RENAMED_KEYS, Leaf, Section, num, schema_of
from supportnode.errors import ConfigError
from supportnode.params import DetectParams
from supportnode.yamlnodes import Constructor, compose, line_of, read_text, short_tag

__all__ = ["load_config", "parse_override"]

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

    def section(self, schema: Section, node: yaml.Node, path: str) -> dict[str, Any]:
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
            if isinstance(field, Section):
                out[key] = self.section(field, value_node, full)
            else:
                out[key] = self.leaf(field, value_node, full)
        return out

    def lookup(
        self, schema: Section, key: str, full: str, node: yaml.Node | None
    ) -> Leaf | Section:
        """The field ``key`` of ``schema``, or an 'unknown key' error with a suggestion."""
        if key in schema.fields:
            return schema.fields[key]
        if full in REMOVED_KEYS:
            raise self.source.fail(node, f"key '{full}' was {REMOVED_KEYS[full]}")
        known = list(schema.fields)
        # A misspelt old name suggests the new one ('voxl_size' -> 'plane_voxel').
        parent = full.rpartition(".")[0]
        renamed = {
            old.rpartition(".")[2]: new.rpartition(".")[2]
            for old, new in RENAMED_KEYS.items()
            if old.rpartition(".")[0] == parent
        }
        close = difflib.get_close_matches(key, known + list(renamed), n=1)
        if close:
            hint = f"did you mean '{renamed.get(close[0], close[0])}'?"
        else:
            hint = "known keys: " + ", ".join(known)
        raise self.source.fail(node, f"unknown key '{full}' ({hint})")

    def leaf(self, leaf: Leaf, node: yaml.Node, path: str) -> Any:
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

    def number(self, leaf: Leaf, kind: type, node: yaml.Node, path: str) -> int | float:
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
                node, f"{path}: {number}{unit} is below the minimum {num(leaf.min)}{unit}"
            )
        if leaf.max is not None and number > leaf.max:
            raise self.source.fail(
                node, f"{path}: {number}{unit} is above the maximum {num(leaf.max)}{unit}"
            )
        return number

    def check_choices(self, leaf: Leaf, value: Any, node: yaml.Node, path: str) -> None:
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

    The value is parsed as YAML (``objects.k=50`` gives 50, ``surfaces.plane_voxel=[0.1,0.1,0.07]``
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
    ``--set`` strings such as ``"surfaces.plane_voxel=[0.1,0.1,0.07]"`` or ``"objects.k=50"``,
    applied in order (a later one wins). ``root_type`` is the root dataclass (default
    `DetectParams`). Raises `ConfigError` with one line naming file:line (or the override) and key.
    """
    schema = schema_of(root_type)
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


def _load_file(schema: Section, path: str) -> dict[str, Any]:
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
    checker: _Checker, schema: Section, key_path: list[str], node: yaml.Node
) -> dict[str, Any]:
    """Check one override's value at ``key_path``; returns it nested as ``{a: {b: value}}``."""
    field: Leaf | Section = schema
    for i, key in enumerate(key_path):
        full = ".".join(key_path[: i + 1])
        if not isinstance(field, Section):
            parent = ".".join(key_path[:i])
            raise checker.source.fail(None, f"unknown key '{full}' ('{parent}' is not a section)")
        field = checker.lookup(field, key, full, None)
    full = ".".join(key_path)
    value: Any = (
        checker.section(field, node, full)
        if isinstance(field, Section)
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


def _build(default: Any, schema: Section, values: dict[str, Any]) -> Any:
    """``default`` with the checked ``values`` (nested dicts for sections) replaced in."""
    changes: dict[str, Any] = {}
    for key, value in values.items():
        field = schema.fields[key]
        if isinstance(field, Section):
            changes[key] = _build(getattr(default, key), field, value)
        else:
            changes[key] = value
    return dataclasses.replace(default, **changes)
