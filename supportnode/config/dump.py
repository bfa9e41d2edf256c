"""Writing the configuration: plain dicts, YAML that loads back, and ``config/default.yaml``.

`dump_default_yaml` is the text of ``config/default.yaml`` and of ``supportnode config dump``:
every key with its default, preceded by its meaning, unit and range or choices. Run
``python -m supportnode.config > config/default.yaml`` to regenerate the file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import textwrap
from typing import Any

import yaml

from supportnode.config.schema import Leaf, Section, num, schema_of
from supportnode.params import DetectParams

_COMMENT_WIDTH = 100


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


def _yaml_value(value: Any) -> str:
    """A key's value as YAML text: a scalar or a flow list of scalars."""
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_yaml_scalar(v) for v in value) + "]"
    return _yaml_scalar(value)


def _describe_limits(leaf: Leaf) -> str:
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
        limits = f"range: [{num(leaf.min)}, {num(leaf.max)}]"
    elif leaf.min is not None:
        limits = f"range: >= {num(leaf.min)}"
    elif leaf.max is not None:
        limits = f"range: <= {num(leaf.max)}"
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


def _dump_section(cfg: Any, schema: Section, indent: str, comments: bool) -> list[str]:
    """The YAML lines of one section instance ``cfg``."""
    lines: list[str] = []
    for name, field in schema.fields.items():
        value = getattr(cfg, name)
        if isinstance(field, Section):
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
    lines = _dump_section(cfg, schema_of(type(cfg)), "", comments)
    return "\n".join(lines) + "\n"


def dump_default_yaml(root_type: type[Any] = DetectParams) -> str:
    """The text of ``config/default.yaml``: every key with its default and a comment."""
    header = [
        "# supportnode configuration: every key with its built-in default.",
        "# Generated from supportnode/params/: python -m supportnode.config > config/default.yaml",
        "# (do not edit by hand; tests/test_config.py checks that this file is up to date).",
        "# Precedence: built-in defaults < YAML file < --set key=value. A config file needs only",
        "# the keys it changes; unknown keys are errors.",
        "",
    ]
    return "\n".join(header) + "\n" + dump_yaml(root_type(), comments=True)
