"""Launch files parsed and checked: `ProcessSpec` per process, errors naming ``file:line``.

See `supportnode.launch` for the file's keys.
"""

from __future__ import annotations

import difflib
import os
import shlex
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from supportnode.errors import ConfigError
from supportnode.yamlnodes import (
    BOOL_TAG,
    FLOAT_TAG,
    INT_TAG,
    STR_TAG,
    Constructor,
    compose,
    describe,
    line_of,
    read_text,
)

__all__ = ["LaunchFile", "ProcessSpec", "load_launch", "resolve_command"]

_KEYS = (
    "name",
    "command",
    "args",
    "config",
    "env",
    "cwd",
    "respawn",
    "respawn_delay",
    "required",
    "delay",
)
_SCALAR_TAGS = (STR_TAG, BOOL_TAG, INT_TAG, FLOAT_TAG)


@dataclass(frozen=True)
class ProcessSpec:
    """One process of a launch file, paths resolved to absolute ones."""

    name: str
    command: tuple[str, ...]  # as resolved by `resolve_command`
    args: tuple[str, ...] = ()
    config: str | None = None
    env: dict[str, str] = field(default_factory=dict)
    cwd: str = "."
    respawn: bool = False
    respawn_delay: float = 1.0  # s
    required: bool = False
    delay: float = 0.0  # s
    is_supportnode: bool = False  # a `supportnode ...` command: receives the --set overrides
    where: str = ""  # "file:line" of its entry, for messages

    def argv(self, overrides: Sequence[str] = ()) -> list[str]:
        """The full command line: command, args, ``--config``, then ``--set`` overrides."""
        out = [*self.command, *self.args]
        if self.config is not None:
            out += ["--config", self.config]
        if self.is_supportnode:
            for text in overrides:
                out += ["--set", text]
        return out


@dataclass(frozen=True)
class LaunchFile:
    """A parsed launch file."""

    path: str
    processes: tuple[ProcessSpec, ...]


def resolve_command(command: Sequence[str]) -> tuple[list[str], bool]:
    """``command`` with ``supportnode`` / ``python`` / ``python3`` as the first word replaced by
    the running interpreter; also whether it is a supportnode command."""
    if not command:
        return [], False
    head, rest = command[0], list(command[1:])
    if head == "supportnode":
        return [sys.executable, "-m", "supportnode", *rest], True
    if head in ("python", "python3"):
        if rest[:2] == ["-m", "supportnode"]:
            return [sys.executable, *rest], True
        return [sys.executable, *rest], False
    return list(command), False


# --------------------------------------------------------------------------------------------
# Parsing.


def load_launch(path: str | os.PathLike[str]) -> LaunchFile:
    """Read and check a launch file; raises `ConfigError` with ``file:line`` on any problem."""
    label = os.fspath(path)
    root = compose(read_text(label, ConfigError), label, ConfigError)
    parser = _Parser(label, Path(label).resolve().parent)
    if root is None:
        raise ConfigError(f"{label}: empty launch file (expected a list of processes)")
    if not isinstance(root, yaml.SequenceNode):
        raise parser.fail(root, f"expected a list of processes, got {describe(root)}")
    specs: list[ProcessSpec] = []
    seen: dict[str, str] = {}
    for item in root.value:
        spec = parser.process(item)
        if spec.name in seen:
            raise parser.fail(
                item, f"duplicate process name '{spec.name}' (first at {seen[spec.name]})"
            )
        seen[spec.name] = spec.where
        specs.append(spec)
    if not specs:
        raise parser.fail(root, "no processes to launch")
    return LaunchFile(path=label, processes=tuple(specs))


class _Parser:
    """Checks composed YAML nodes of one launch file."""

    def __init__(self, label: str, folder: Path) -> None:
        self.label = label
        self.folder = folder
        self._values = Constructor()

    def fail(self, node: yaml.Node, message: str) -> ConfigError:
        return ConfigError(f"{self.label}:{line_of(node)}: {message}")

    def process(self, node: yaml.Node) -> ProcessSpec:
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(node, f"expected a process (a mapping of keys), got {describe(node)}")
        values: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for key_node, value_node in node.value:
            key = str(key_node.value) if isinstance(key_node, yaml.ScalarNode) else "?"
            if key not in _KEYS:
                close = difflib.get_close_matches(key, _KEYS, n=1)
                hint = f"did you mean '{close[0]}'?" if close else "known keys: " + ", ".join(_KEYS)
                raise self.fail(key_node, f"unknown key '{key}' ({hint})")
            if key in values:
                raise self.fail(key_node, f"duplicate key '{key}'")
            values[key] = (key_node, value_node)
        for key in ("name", "command"):
            if key not in values:
                raise self.fail(node, f"process without '{key}'")
        name = self.text(values["name"][1], "name")
        if not name or any(c.isspace() for c in name):
            raise self.fail(values["name"][1], f"name: expected one word, got {name!r}")
        where = f"{self.label}:{node.start_mark.line + 1}"
        command_node = values["command"][1]
        if isinstance(command_node, yaml.SequenceNode):
            words = self.words(command_node, "command")
        else:
            try:
                words = shlex.split(self.text(command_node, "command"))
            except ValueError as err:
                raise self.fail(command_node, f"command: {err}") from err
        if not words:
            raise self.fail(command_node, "command: empty")
        command, is_supportnode = resolve_command(words)
        opt: dict[str, Any] = {}
        if "args" in values:
            opt["args"] = tuple(self.words(values["args"][1], "args"))
        if "config" in values:
            config = self.text(values["config"][1], "config")
            opt["config"] = os.path.normpath(self.folder / config)
        if "env" in values:
            opt["env"] = self.env(values["env"][1])
        cwd = self.text(values["cwd"][1], "cwd") if "cwd" in values else "."
        opt["cwd"] = os.path.normpath(self.folder / cwd)
        for key in ("respawn", "required"):
            if key in values:
                opt[key] = self.boolean(values[key][1], key)
        for key in ("respawn_delay", "delay"):
            if key in values:
                opt[key] = self.seconds(values[key][1], key)
        if opt.get("respawn") and opt.get("required"):
            raise self.fail(node, f"process '{name}': respawn and required exclude each other")
        return ProcessSpec(
            name=name,
            command=tuple(command),
            is_supportnode=is_supportnode,
            where=where,
            **opt,
        )

    def value(self, node: yaml.ScalarNode) -> Any:
        return self._values.value(node)

    def text(self, node: yaml.Node, key: str) -> str:
        if not isinstance(node, yaml.ScalarNode) or node.tag != STR_TAG:
            raise self.fail(node, f"{key}: expected a string, got {describe(node)}")
        return str(node.value)

    def words(self, node: yaml.Node, key: str) -> list[str]:
        """A list of scalars, each taken as written (``0.10`` stays ``0.10``)."""
        if not isinstance(node, yaml.SequenceNode):
            raise self.fail(node, f"{key}: expected a list, got {describe(node)}")
        out = []
        for item in node.value:
            if not isinstance(item, yaml.ScalarNode) or item.tag not in _SCALAR_TAGS:
                raise self.fail(item, f"{key}: expected strings or numbers, got {describe(item)}")
            out.append(str(item.value))
        return out

    def env(self, node: yaml.Node) -> dict[str, str]:
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(node, f"env: expected a mapping NAME: value, got {describe(node)}")
        out: dict[str, str] = {}
        for key_node, value_node in node.value:
            name = str(key_node.value) if isinstance(key_node, yaml.ScalarNode) else ""
            if not name or "=" in name:
                raise self.fail(key_node, f"env: bad variable name {name!r}")
            if not isinstance(value_node, yaml.ScalarNode) or value_node.tag not in _SCALAR_TAGS:
                raise self.fail(value_node, f"env.{name}: expected a string or number")
            out[name] = str(value_node.value)
        return out

    def boolean(self, node: yaml.Node, key: str) -> bool:
        if not isinstance(node, yaml.ScalarNode) or node.tag != BOOL_TAG:
            raise self.fail(node, f"{key}: expected true or false, got {describe(node)}")
        return bool(self.value(node))

    def seconds(self, node: yaml.Node, key: str) -> float:
        if not isinstance(node, yaml.ScalarNode) or node.tag not in (INT_TAG, FLOAT_TAG):
            raise self.fail(node, f"{key}: expected a number of seconds, got {describe(node)}")
        value = float(self.value(node))
        if not (0.0 <= value < float("inf")):
            raise self.fail(node, f"{key}: expected a finite number >= 0 s, got {node.value}")
        return value
