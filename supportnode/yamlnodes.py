"""The one line-aware YAML loader: config files, launch files and scenes all read YAML here.

PyYAML's composed nodes keep where each key and value stands, so every error can name
``file:line``. This module reads a file, composes its text (syntax errors as one line with
the line number), constructs plain values of scalar nodes (unsupported tags as one line), and
builds `LineMap`/`LineSeq` trees that remember their lines, for readers that walk values
rather than nodes. Each caller passes its own error class (`ConfigError`, `SceneError`), so
its users keep catching what they caught.
"""

from __future__ import annotations

import os
from typing import Any

import yaml

from supportnode.errors import SupportNodeError

__all__ = [
    "BOOL_TAG",
    "FLOAT_TAG",
    "INT_TAG",
    "MAP_TAG",
    "NULL_TAG",
    "SEQ_TAG",
    "STR_TAG",
    "Constructor",
    "LineMap",
    "LineSeq",
    "compose",
    "describe",
    "line_of",
    "line_tree",
    "read_text",
    "short_tag",
]

NULL_TAG = "tag:yaml.org,2002:null"
STR_TAG = "tag:yaml.org,2002:str"
BOOL_TAG = "tag:yaml.org,2002:bool"
INT_TAG = "tag:yaml.org,2002:int"
FLOAT_TAG = "tag:yaml.org,2002:float"
MAP_TAG = "tag:yaml.org,2002:map"
SEQ_TAG = "tag:yaml.org,2002:seq"
_MERGE_TAG = "tag:yaml.org,2002:merge"


def read_text(path: str | os.PathLike[str], error: type[SupportNodeError]) -> str:
    """The UTF-8 text of ``path``; ``error`` with one line naming the path on any problem."""
    label = os.fspath(path)
    try:
        with open(label, encoding="utf-8") as fh:
            return fh.read()
    except FileNotFoundError as err:
        raise error(f"{label}: no such file") from err
    except IsADirectoryError as err:
        raise error(f"{label}: is a directory, not a YAML file") from err
    except UnicodeDecodeError as err:
        raise error(f"{label}: not UTF-8 text ({err.reason} at byte {err.start})") from err
    except OSError as err:
        raise error(f"{label}: cannot read ({err.strerror})") from err


def compose(text: str, label: str, error: type[SupportNodeError]) -> yaml.Node | None:
    """The root node of YAML ``text`` (None when it holds no document, e.g. only comments).

    Syntax errors raise ``error("label:line: YAML syntax error: ...")``.
    """
    try:
        return yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f"{label}:{mark.line + 1}" if mark is not None else label
        problem = ", ".join(p for p in (err.context, err.problem) if p)
        raise error(f"{where}: YAML syntax error: {problem}") from err
    except yaml.YAMLError as err:
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise error(f"{label}: YAML error: {first}") from err


def line_of(node: yaml.Node | None) -> int:
    """1-based line where ``node`` starts (0 when unknown)."""
    if node is None or node.start_mark is None:
        return 0
    return int(node.start_mark.line) + 1


def short_tag(tag: str) -> str:
    """A tag as written in YAML: ``tag:yaml.org,2002:int`` -> ``!!int``."""
    return "!!" + tag.removeprefix("tag:yaml.org,2002:") if tag.startswith("tag:yaml.org") else tag


def describe(node: yaml.Node) -> str:
    """What a node holds, for messages: ``a mapping``, ``a list of 3 items``, ``'text'``, ..."""
    if isinstance(node, yaml.MappingNode):
        return "a mapping"
    if isinstance(node, yaml.SequenceNode):
        return f"a list of {len(node.value)} items"
    if node.tag == NULL_TAG:
        return "nothing (null)"
    return repr(node.value) if node.tag == STR_TAG else str(node.value)


class Constructor:
    """Plain Python values of composed nodes, as ``yaml.safe_load`` would build them."""

    def __init__(self) -> None:
        self._loader = yaml.SafeLoader("")

    def close(self) -> None:
        """Release PyYAML's loader state."""
        self._loader.dispose()

    def __enter__(self) -> Constructor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def value(self, node: yaml.Node) -> Any:
        """The value of ``node``; PyYAML's own errors propagate (see `checked`)."""
        return self._loader.construct_object(node, deep=True)

    def checked(self, node: yaml.Node, fail: Any) -> Any:
        """The value of ``node``; a tag the safe loader cannot build (``!!python/...``,
        ``!foo``, ``!!int abc``) calls ``fail(node, problem)``, which must return the
        exception to raise (problem: ``tag not supported`` or the constructor's reason)."""
        try:
            return self.value(node)
        except Exception as err:  # PyYAML's constructors raise many kinds on bad tagged text
            if isinstance(err, yaml.constructor.ConstructorError):
                problem = "tag not supported"
            elif isinstance(err, ValueError):
                problem = str(err)
            else:
                problem = "not a valid value for this tag"
            raise fail(node, problem) from err


class LineMap(dict):  # type: ignore[type-arg]
    """A mapping that remembers its own line and each key's line (1-based)."""

    line: int = 0
    key_lines: dict[Any, int]


class LineSeq(list):  # type: ignore[type-arg]
    """A list that remembers its own line and each item's line (1-based)."""

    line: int = 0
    item_lines: list[int]


def line_tree(
    node: yaml.Node | None, label: str, error: type[SupportNodeError]
) -> Any:  # LineMap | LineSeq | scalar
    """Plain values of a composed tree, mappings as `LineMap` and lists as `LineSeq`.

    Merge keys (``<<: *base``) are expanded; a duplicate key raises
    ``error("label:line: duplicate key 'k'")``; an unsupported tag raises
    ``error("label:line: cannot read ...")``. None (no document) gives None.
    """
    if node is None:
        return None
    with Constructor() as ctor:
        return _tree(ctor, node, label, error)


def _tree(ctor: Constructor, node: yaml.Node, label: str, error: type[SupportNodeError]) -> Any:
    if isinstance(node, yaml.MappingNode) and node.tag == MAP_TAG:
        own = sum(1 for k, _ in node.value if k.tag != _MERGE_TAG)
        ctor._loader.flatten_mapping(node)  # merged pairs first, then the node's own
        merged = len(node.value) - own  # own keys override merged ones (YAML merge rules)
        m = LineMap()
        m.line, m.key_lines = line_of(node), {}
        from_merge: set[Any] = set()  # keys a merged mapping set, not yet overridden
        for i, (k_node, v_node) in enumerate(node.value):
            key = _tree(ctor, k_node, label, error)
            if isinstance(key, (LineMap, LineSeq)):
                raise error(
                    f"{label}:{line_of(k_node)}: a key must be a scalar, got {describe(k_node)}"
                )
            if key in m and i >= merged and key not in from_merge:
                raise error(f"{label}:{line_of(k_node)}: duplicate key {key!r}")
            if i < merged:
                from_merge.add(key)
            else:
                from_merge.discard(key)
            m[key] = _tree(ctor, v_node, label, error)
            m.key_lines[key] = line_of(k_node)
        return m
    if isinstance(node, yaml.SequenceNode) and node.tag == SEQ_TAG:
        s = LineSeq(_tree(ctor, n, label, error) for n in node.value)
        s.line, s.item_lines = line_of(node), [line_of(n) for n in node.value]
        return s

    def fail(n: yaml.Node, problem: str) -> SupportNodeError:
        what = n.value if isinstance(n, yaml.ScalarNode) else describe(n)
        return error(
            f"{label}:{line_of(n)}: cannot read {what!r} tagged {short_tag(n.tag)} ({problem})"
        )

    return ctor.checked(node, fail)
