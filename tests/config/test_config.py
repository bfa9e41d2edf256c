"""Tests of the strict typed configuration (supportnode.config)."""

from __future__ import annotations

import dataclasses
import json
import re
import textwrap
import typing
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from supportnode.config import (
    RENAMED_KEYS,
    config_to_dict,
    dump_default_yaml,
    dump_yaml,
    load_config,
    parse_override,
)
from supportnode.errors import ConfigError, SupportNodeError
from supportnode.params import DetectParams, FreeSpaceParams, ObjectParams, SurfaceParams

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"


def write(tmp_path: Path, text: str, name: str = "my.yaml") -> Path:
    """Write dedented YAML ``text`` (less one leading newline) to ``tmp_path``; return its path."""
    path = tmp_path / name
    path.write_text(textwrap.dedent(text).removeprefix("\n"), encoding="utf-8")
    return path


def config_error(path: Any = None, overrides: tuple[str, ...] = ()) -> str:
    """The message of the ConfigError that loading raises (fails if nothing is raised)."""
    with pytest.raises(ConfigError) as info:
        load_config(path, overrides)
    message = str(info.value)
    assert "\n" not in message
    return message


def leaves(cls: type, prefix: str = "") -> list[tuple[str, dataclasses.Field[Any], Any]]:
    """Every (dotted key, field, type hint) of the dataclass tree ``cls``."""
    out = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            out += leaves(hint, f"{prefix}{f.name}.")
        else:
            out.append((f"{prefix}{f.name}", f, hint))
    return out


# ---------------------------------------------------------------------------------------------
# Defaults and precedence


def test_no_file_gives_defaults() -> None:
    assert load_config() == DetectParams()
    assert load_config(None, ()) == DetectParams()


@pytest.mark.parametrize("text", ["", "\n", "# only a comment\n", "---\n", "~\n"])
def test_empty_file_gives_defaults(tmp_path: Path, text: str) -> None:
    assert load_config(write(tmp_path, text)) == DetectParams()


def test_yaml_overrides_defaults(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """
        surfaces:
          method: seed
          plane_voxel: [0.1, 0.1, 0.07]
          max_step: 1      # an integer is fine for a float
          normal_filter: true
        objects:
          k: 50
        gravity:
          up_hint:
            - 0
            - 0
            - 1
        """,
    )
    cfg = load_config(str(path))
    assert cfg.surfaces == dataclasses.replace(
        SurfaceParams(),
        method="seed",
        plane_voxel=(0.1, 0.1, 0.07),
        max_step=1.0,
        normal_filter=True,
    )
    assert isinstance(cfg.surfaces.max_step, float)
    assert cfg.objects == dataclasses.replace(ObjectParams(), k=50)
    assert cfg.gravity.up_hint == (0.0, 0.0, 1.0)
    assert cfg.freespace == FreeSpaceParams()


def test_null_section_means_defaults(tmp_path: Path) -> None:
    path = write(tmp_path, "surfaces:\n  # method: seed\nobjects:\n  k: 7\n")
    assert load_config(path) == dataclasses.replace(DetectParams(), objects=ObjectParams(k=7))


def test_exponent_without_dot_is_a_number(tmp_path: Path) -> None:
    # PyYAML (YAML 1.1) reads 1e-3 as text; people mean a number.
    path = write(tmp_path, "surfaces:\n  max_step: 1e-3\n  max_roughness: 2.5E-2\n")
    cfg = load_config(path)
    assert cfg.surfaces.max_step == 0.001
    assert cfg.surfaces.max_roughness == 0.025
    quoted = write(tmp_path, "surfaces:\n  max_step: '1e-3'\n", "quoted.yaml")
    assert config_error(quoted) == f"{quoted}:2: surfaces.max_step: expected a number, got '1e-3'"


def test_set_beats_yaml_beats_defaults(tmp_path: Path) -> None:
    path = write(tmp_path, "objects:\n  k: 40\n  seed: 3\n")
    cfg = load_config(path, ["objects.k=50", "surfaces.method=seed"])
    assert cfg.objects.k == 50  # --set over YAML
    assert cfg.objects.seed == 3  # YAML over default
    assert cfg.objects.min_points == ObjectParams().min_points  # default
    assert cfg.surfaces.method == "seed"


def test_later_set_wins_and_sections_can_be_set_whole() -> None:
    cfg = load_config(None, ["objects.k=5", "objects.k=6", "surfaces={method: seed, p_min: 4}"])
    assert cfg.objects.k == 6
    assert (cfg.surfaces.method, cfg.surfaces.p_min) == ("seed", 4)
    assert cfg.surfaces.plane_voxel == SurfaceParams().plane_voxel


def test_report_overrides_from_the_brief() -> None:
    cfg = load_config(
        None, ["surfaces.plane_voxel=[0.1,0.1,0.07]", "objects.k=50", "surfaces.method=seed"]
    )
    assert cfg.surfaces.plane_voxel == (0.1, 0.1, 0.07)
    assert cfg.objects.k == 50
    assert cfg.surfaces.method == "seed"


def test_pathlike_and_root_type(tmp_path: Path) -> None:
    path = write(tmp_path, "margin: 0.12\n")
    assert load_config(path, (), FreeSpaceParams) == FreeSpaceParams(margin=0.12)
    assert load_config(path, ["margin=0.13"], root_type=FreeSpaceParams) == FreeSpaceParams(
        margin=0.13
    )


# ---------------------------------------------------------------------------------------------
# parse_override


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("surfaces.plane_voxel=[0.1,0.1,0.07]", (["surfaces", "plane_voxel"], [0.1, 0.1, 0.07])),
        ("objects.k=50", (["objects", "k"], 50)),
        ("surfaces.method=seed", (["surfaces", "method"], "seed")),
        ("surfaces.normal_filter=true", (["surfaces", "normal_filter"], True)),
        ("objects.sample_fraction = 0.5", (["objects", "sample_fraction"], 0.5)),
        ("a.b=x=y", (["a", "b"], "x=y")),
        ("a=", (["a"], None)),
    ],
)
def test_parse_override(text: str, expected: tuple[list[str], Any]) -> None:
    assert parse_override(text) == expected


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("objects.k", "--set objects.k: expected key=value, e.g. --set surfaces.method=seed"),
        ("=3", "--set =3: expected key=value, e.g. --set surfaces.method=seed"),
        (
            "objects..k=3",
            "--set objects..k=3: malformed key 'objects..k' (expected names joined by dots)",
        ),
        (
            "objects.k=[1",
            "--set objects.k=[1: cannot parse the value as YAML: expected ',' or ']', but got '<stream end>'",
        ),
    ],
)
def test_parse_override_errors(text: str, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_override(text)
    assert str(info.value) == message
    assert config_error(None, (text,)) == message


# ---------------------------------------------------------------------------------------------
# File errors: exact line and key


def test_unknown_key_names_file_line_and_suggestion(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """
        # my settings
        surfaces:
          method: seed
          p_min: 3

          # finer voxels
          plane_voxl: [0.1, 0.1, 0.07]
        """,
    )
    assert config_error(path) == (
        f"{path}:7: unknown key 'surfaces.plane_voxl' (did you mean 'plane_voxel'?)"
    )


@pytest.mark.parametrize(
    ("old", "new", "value", "expected"),
    [
        ("surfaces.voxel_size", "surfaces.plane_voxel", "[0.1, 0.1, 0.07]", (0.1, 0.1, 0.07)),
        ("objects.voxel_size", "objects.cluster_cell", "0.05", 0.05),
        ("gravity.voxel_size", "gravity.downsample_voxel", "0.1", 0.1),
    ],
)
def test_renamed_keys_name_their_replacement(
    tmp_path: Path, old: str, new: str, value: str, expected: Any
) -> None:
    assert RENAMED_KEYS[old] == new
    section, name = old.split(".")
    path = write(tmp_path, f"{section}:\n  {name}: {value}\n")
    assert config_error(path) == f"{path}:2: key '{old}' was renamed in 0.2: use '{new}'"
    assert config_error(None, (f"{old}={value}",)) == (
        f"--set {old}={value}: key '{old}' was renamed in 0.2: use '{new}'"
    )
    cfg = load_config(None, (f"{new}={value}",))
    assert getattr(getattr(cfg, section), new.split(".")[1]) == expected


def test_unknown_section_suggests_and_lists(tmp_path: Path) -> None:
    path = write(tmp_path, "objects:\n  k: 3\nsurface:\n  method: seed\n")
    assert config_error(path) == f"{path}:3: unknown key 'surface' (did you mean 'surfaces'?)"
    path = write(tmp_path, "freespace:\n  zzz: 1\n")
    assert config_error(path) == (
        f"{path}:2: unknown key 'freespace.zzz' (known keys: cell_size, margin)"
    )


def test_wrong_type_names_line_and_key(tmp_path: Path) -> None:
    path = write(tmp_path, "# line\n" * 7 + "surfaces:\n  p_min: two\n")
    assert config_error(path) == f"{path}:9: surfaces.p_min: expected an integer, got 'two'"


def test_not_in_choices(tmp_path: Path) -> None:
    path = write(tmp_path, "# my\n\nsurfaces:\n  method: sed\n")
    assert config_error(path) == f"{path}:4: surfaces.method: 'sed' is not one of seed, planar"
    path = write(tmp_path, "surfaces:\n  connectivity: 6\n")
    assert config_error(path) == f"{path}:2: surfaces.connectivity: 6 is not one of 4, 8"


def test_out_of_range(tmp_path: Path) -> None:
    path = write(tmp_path, "objects:\n  k: 0\n  sample_fraction: 0.5\n")
    assert config_error(path) == f"{path}:2: objects.k: 0 is below the minimum 1"
    path = write(tmp_path, "surfaces:\n  max_tilt_deg: 90\n")
    assert config_error(path) == (
        f"{path}:2: surfaces.max_tilt_deg: 90.0 deg is above the maximum 89 deg"
    )


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("objects:\n  k: yes\n", "objects.k: expected an integer, got yes (a boolean)"),
        ("objects:\n  k: true\n", "objects.k: expected an integer, got true (a boolean)"),
        ("objects:\n  k: 2.5\n", "objects.k: expected an integer, got 2.5"),
        ("objects:\n  k:\n", "objects.k: expected an integer, got nothing (null)"),
        ("objects:\n  k: [1]\n", "objects.k: expected an integer, got a list of 1 items"),
        ("objects:\n  k: {a: 1}\n", "objects.k: expected an integer, got a mapping"),
        ("objects:\n  k: '5'\n", "objects.k: expected an integer, got '5'"),
        ("surfaces:\n  max_step: no\n", "surfaces.max_step: expected a number, got no (a boolean)"),
        ("surfaces:\n  max_step: .inf\n", "surfaces.max_step: expected a finite number, got inf"),
        (
            "surfaces:\n  normal_filter: 1\n",
            "surfaces.normal_filter: expected true or false, got 1",
        ),
        (
            "node:\n  scan_bind: maybe\n",
            "node.scan_bind: expected true or false, got 'maybe'",
        ),
        (
            "node:\n  pub_bind: 2\n",
            "node.pub_bind: expected true or false, got 2",
        ),
        (
            "surfaces:\n  normal_filter: 'true'\n",
            "surfaces.normal_filter: expected true or false, got 'true'",
        ),
        ("surfaces:\n  method: 1\n", "surfaces.method: expected a string, got 1"),
        (
            "surfaces:\n  plane_voxel: 0.1\n",
            "surfaces.plane_voxel: expected a list of 3 numbers, got 0.1",
        ),
        (
            "surfaces:\n  plane_voxel: [0.1, 0.1]\n",
            "surfaces.plane_voxel: expected a list of 3 numbers, got a list of 2 items",
        ),
        (
            "surfaces:\n  plane_voxel: [0.1, 0.1, 0]\n",
            "surfaces.plane_voxel[2]: 0.0 m is below the minimum 0.001 m",
        ),
    ],
)
def test_wrong_values(tmp_path: Path, body: str, message: str) -> None:
    path = write(tmp_path, body)
    assert config_error(path) == f"{path}:2: {message}"


def test_tuple_element_error_names_its_own_line(tmp_path: Path) -> None:
    path = write(tmp_path, "surfaces:\n  plane_voxel:\n    - 0.1\n    - x\n    - 0.07\n")
    assert config_error(path) == f"{path}:4: surfaces.plane_voxel[1]: expected a number, got 'x'"


def test_section_given_as_scalar(tmp_path: Path) -> None:
    path = write(tmp_path, "objects:\n  k: 3\nsurfaces: 0.1\n")
    assert config_error(path) == (
        f"{path}:3: surfaces: expected a section (a mapping of keys), got 0.1"
    )
    path = write(tmp_path, "surfaces:\n  - method\n")
    assert config_error(path) == (
        f"{path}:2: surfaces: expected a section (a mapping of keys), got a list of 1 items"
    )


def test_top_level_not_a_mapping(tmp_path: Path) -> None:
    path = write(tmp_path, "# settings\n- surfaces\n- objects\n")
    assert config_error(path) == (
        f"{path}:2: expected sections at the top level (a mapping of keys), got a list of 2 items"
    )
    path = write(tmp_path, "hello\n")
    assert config_error(path) == (
        f"{path}:1: expected sections at the top level (a mapping of keys), got 'hello'"
    )


def test_yaml_syntax_error_reports_pyyaml_line(tmp_path: Path) -> None:
    path = write(tmp_path, "surfaces:\n  method: seed\n  p_min: [1, 2\nobjects:\n  k: 3\n")
    message = config_error(path)
    assert message.startswith(f"{path}:4: YAML syntax error: ")
    assert "expected ',' or ']'" in message
    path = write(tmp_path, "surfaces:\n  method: seed\n\tp_min: 3\n")
    assert config_error(path).startswith(f"{path}:3: YAML syntax error: ")


def test_two_documents_is_an_error(tmp_path: Path) -> None:
    path = write(tmp_path, "objects:\n  k: 3\n---\nobjects:\n  k: 4\n")
    assert config_error(path).startswith(f"{path}:3: YAML syntax error: ")


def test_duplicate_key(tmp_path: Path) -> None:
    path = write(tmp_path, "objects:\n  k: 3\n  seed: 1\n  k: 4\n")
    assert config_error(path) == f"{path}:4: duplicate key 'objects.k' (first given at line 2)"


def test_merge_keys_rejected(tmp_path: Path) -> None:
    path = write(tmp_path, "base: &b {k: 3}\nobjects:\n  <<: *b\n")
    assert config_error(path) == f"{path}:1: unknown key 'base' (known keys: " + (
        "surfaces, objects, freespace, gravity, safe, node)"
    )
    path = write(tmp_path, "objects: &b\n  k: 3\nfreespace:\n  <<: *b\n")
    assert config_error(path) == f"{path}:4: YAML merge keys ('<<') are not supported"


def test_missing_file_and_directory(tmp_path: Path) -> None:
    missing = tmp_path / "nope.yaml"
    assert config_error(missing) == f"{missing}: no such file"
    assert config_error(tmp_path) == f"{tmp_path}: is a directory, not a YAML file"


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes("surfaces:\n  method: s\xe9ed\n".encode("latin-1"))
    assert config_error(path).startswith(f"{path}: not UTF-8 text")


def test_config_error_is_a_supportnode_error(tmp_path: Path) -> None:
    with pytest.raises(SupportNodeError):
        load_config(tmp_path / "nope.yaml")


# ---------------------------------------------------------------------------------------------
# --set errors: same checks, named by the override


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "surfaces.voxl_size=[0.1,0.1,0.07]",
            "unknown key 'surfaces.voxl_size' (did you mean 'plane_voxel'?)",
        ),
        ("surfce.method=seed", "unknown key 'surfce' (did you mean 'surfaces'?)"),
        ("objects.kk=3", "unknown key 'objects.kk' (did you mean 'k'?)"),
        ("objects.k=two", "objects.k: expected an integer, got 'two'"),
        ("objects.k=yes", "objects.k: expected an integer, got yes (a boolean)"),
        ("objects.k=", "objects.k: expected an integer, got nothing (null)"),
        ("surfaces.method=sed", "surfaces.method: 'sed' is not one of seed, planar"),
        ("objects.k=501", "objects.k: 501 is above the maximum 500"),
        ("surfaces.plane_voxel=0.1", "surfaces.plane_voxel: expected a list of 3 numbers, got 0.1"),
        ("surfaces=3", "surfaces: expected a section (a mapping of keys), got 3"),
        (
            "surfaces.method.x=1",
            "unknown key 'surfaces.method.x' ('surfaces.method' is not a section)",
        ),
        ("surfaces={p_min: x}", "surfaces.p_min: expected an integer, got 'x'"),
    ],
)
def test_set_errors_name_the_override(tmp_path: Path, text: str, message: str) -> None:
    assert config_error(None, (text,)) == f"--set {text}: {message}"
    # The file is fine; the bad override is still reported as the override.
    path = write(tmp_path, "objects:\n  k: 3\n")
    assert config_error(path, ("objects.seed=1", text)) == f"--set {text}: {message}"


# ---------------------------------------------------------------------------------------------
# config_to_dict and dump_yaml


def test_config_to_dict_is_plain_and_json_ready() -> None:
    cfg = DetectParams()
    d = config_to_dict(cfg)
    assert d["surfaces"]["plane_voxel"] == [0.1, 0.1, 0.05]
    assert d["objects"]["method"] == "convex"
    assert set(d) == {f.name for f in dataclasses.fields(DetectParams)}
    assert json.loads(json.dumps(d)) == d
    with pytest.raises(TypeError):
        config_to_dict({"a": 1})


def test_saved_result_dict_loads_back(tmp_path: Path) -> None:
    # result.json holds config_to_dict(cfg); as YAML (JSON is YAML) it loads back to cfg.
    cfg = load_config(CONFIG_DIR / "report.yaml")
    path = tmp_path / "result_config.json"
    path.write_text(json.dumps(config_to_dict(cfg), indent=2), encoding="utf-8")
    assert load_config(path) == cfg


def test_dump_yaml_without_comments_round_trips(tmp_path: Path) -> None:
    cfg = load_config(CONFIG_DIR / "noisy.yaml")
    text = dump_yaml(cfg, comments=False)
    assert "#" not in text
    assert load_config(write(tmp_path, text)) == cfg


# ---------------------------------------------------------------------------------------------
# Property: every valid configuration survives dump -> load, through a file and through --set


def field_strategy(f: dataclasses.Field[Any], hint: Any, default: Any) -> st.SearchStrategy[Any]:
    """Valid values of one field, from its type and its metadata (min/max/choices)."""
    meta = f.metadata
    if "choices" in meta:
        return st.sampled_from(meta["choices"])
    lo, hi = meta.get("min"), meta.get("max")
    if hint is bool:
        return st.booleans()
    if hint is int:
        return st.integers(min_value=lo, max_value=hi)
    if hint is str:
        return st.text()
    floats = st.floats(min_value=lo, max_value=hi, allow_nan=False, allow_infinity=False)
    if hint is float:
        return floats
    assert typing.get_origin(hint) is tuple, hint
    return st.tuples(*[floats] * len(default))


def config_strategy(cls: type) -> st.SearchStrategy[Any]:
    """Valid instances of the dataclass tree ``cls``."""
    hints = typing.get_type_hints(cls)
    defaults = cls()
    kwargs = {}
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            kwargs[f.name] = config_strategy(hint)
        else:
            kwargs[f.name] = field_strategy(f, hint, getattr(defaults, f.name))
    return st.builds(cls, **kwargs)


def same(a: Any, b: Any) -> bool:
    """Equal configurations, with values and types (an int must not come back as a float)."""
    return a == b and json.dumps(config_to_dict(a)) == json.dumps(config_to_dict(b))


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(cfg=config_strategy(DetectParams))
def test_property_dump_then_load_is_identity(tmp_path: Path, cfg: DetectParams) -> None:
    path = tmp_path / "round.yaml"
    path.write_text(dump_yaml(cfg), encoding="utf-8")
    assert same(load_config(path), cfg)


@settings(max_examples=100, deadline=None)
@given(cfg=config_strategy(DetectParams))
def test_property_every_value_survives_set(cfg: DetectParams) -> None:
    overrides = []
    for key, _, _ in leaves(DetectParams):
        value: Any = cfg
        for part in key.split("."):
            value = getattr(value, part)
        text = yaml.safe_dump(
            list(value) if isinstance(value, tuple) else value, default_flow_style=True
        )
        overrides.append(f"{key}={text.removesuffix(chr(10) + '...' + chr(10)).strip()}")
    assert same(load_config(None, overrides), cfg)


@settings(max_examples=50, deadline=None)
@given(value=st.floats(allow_nan=False, allow_infinity=False, min_value=1e-3, max_value=10.0))
def test_property_float_text_is_yaml_11_float(value: float) -> None:
    # Whatever repr gives (1e-05, 1e+20), the dumped text must load as the same float.
    text = dump_yaml(
        dataclasses.replace(DetectParams(), surfaces=SurfaceParams(max_step=value * 1e-6))
    )
    assert yaml.safe_load(text)["surfaces"]["max_step"] == value * 1e-6


# ---------------------------------------------------------------------------------------------
# Generic over new sections and field types


@dataclasses.dataclass(frozen=True)
class NodeSection:
    """A section a later version may add."""

    rate_hz: float = dataclasses.field(
        default=10.0, metadata={"help": "rate", "unit": "Hz", "min": 0.0}
    )
    name: str = dataclasses.field(default="node", metadata={"help": "name"})
    origin: tuple[float, ...] = dataclasses.field(
        default=(0.0, 0.0), metadata={"help": "2-D origin", "unit": "m"}
    )


@dataclasses.dataclass(frozen=True)
class BiggerRoot:
    """A root with the detection sections plus one more."""

    surfaces: SurfaceParams = dataclasses.field(default_factory=SurfaceParams)
    node: NodeSection = dataclasses.field(default_factory=NodeSection)


def test_new_section_is_just_a_new_field(tmp_path: Path) -> None:
    path = write(tmp_path, "node:\n  rate_hz: 5\n  name: 'robot: 1'\n  origin: [1, 2]\n")
    cfg = load_config(path, ["surfaces.method=seed"], BiggerRoot)
    assert cfg == BiggerRoot(SurfaceParams(method="seed"), NodeSection(5.0, "robot: 1", (1.0, 2.0)))
    text = dump_default_yaml(BiggerRoot)
    assert "node:\n" in text and "# (number, unit: Hz, range: >= 0)" in text
    assert load_config(write(tmp_path, text, "d.yaml"), (), BiggerRoot) == BiggerRoot()
    assert load_config(write(tmp_path, dump_yaml(cfg), "c.yaml"), (), BiggerRoot) == cfg
    bad = write(tmp_path, "node:\n  origin: [1, 2, 3]\n", "bad.yaml")
    assert config_error_root(bad, BiggerRoot) == (
        f"{bad}:2: node.origin: expected a list of 2 numbers, got a list of 3 items"
    )


def config_error_root(path: Path, root: type) -> str:
    """The ConfigError message of loading ``path`` as ``root``."""
    with pytest.raises(ConfigError) as info:
        load_config(path, (), root)
    return str(info.value)


def test_unsupported_field_type_is_a_programming_error() -> None:
    @dataclasses.dataclass(frozen=True)
    class Bad:
        items: list[int] = dataclasses.field(default_factory=list)

    with pytest.raises(TypeError, match="unsupported configuration type"):
        load_config(None, (), Bad)


# ---------------------------------------------------------------------------------------------
# The committed config files


def test_default_yaml_is_up_to_date() -> None:
    committed = (CONFIG_DIR / "default.yaml").read_text(encoding="utf-8")
    assert committed == dump_default_yaml(), (
        "config/default.yaml is stale: python -m supportnode.config > config/default.yaml"
    )


def test_default_yaml_loads_back_to_the_defaults() -> None:
    assert load_config(CONFIG_DIR / "default.yaml") == DetectParams()


def test_default_yaml_documents_every_field() -> None:
    lines = (CONFIG_DIR / "default.yaml").read_text(encoding="utf-8").splitlines()
    index = {}  # dotted key -> line number, from indentation
    stack: list[str] = []
    for i, line in enumerate(lines):
        m = re.match(r"( *)([a-z_0-9]+):", line)
        if m:
            depth = len(m.group(1)) // 2
            stack = [*stack[:depth], m.group(2)]
            index[".".join(stack)] = i
    for key, f, _ in leaves(DetectParams):
        assert key in index, f"{key} missing from default.yaml"
        i = index[key]
        comment = []
        while lines[i - 1].lstrip().startswith("#"):
            i -= 1
            comment.insert(0, lines[i].strip().lstrip("# "))
        text = " ".join(comment)
        assert " ".join(f.metadata["help"].split()) in text, key
        if f.metadata.get("unit"):
            assert f"unit: {f.metadata['unit']}" in text, key
        if "choices" in f.metadata:
            assert "one of: " + ", ".join(map(str, f.metadata["choices"])) in text, key
        for limit in ("min", "max"):
            if limit in f.metadata:
                assert f"{f.metadata[limit]:g}" in text, key


def test_noisy_yaml() -> None:
    cfg = load_config(CONFIG_DIR / "noisy.yaml")
    s = cfg.surfaces
    assert s.plane_voxel[2] in (0.07, 0.1)
    assert s.max_roughness == pytest.approx(0.03)
    assert s.point_tolerance == pytest.approx(0.05)
    assert s.max_step == pytest.approx(0.05)


def test_report_yaml() -> None:
    cfg = load_config(CONFIG_DIR / "report.yaml")
    assert cfg.surfaces.method == "seed"
    assert cfg.surfaces.plane_voxel == (0.1, 0.1, 0.07)
    assert cfg.objects.method == "knn"
    assert cfg.objects.k == 50
    assert cfg.objects.sample_fraction == 0.3


@pytest.mark.parametrize("name", ["noisy.yaml", "report.yaml"])
def test_tuned_files_hold_only_changed_keys(name: str) -> None:
    data = yaml.safe_load((CONFIG_DIR / name).read_text(encoding="utf-8"))
    defaults = config_to_dict(DetectParams())
    for section, keys in data.items():
        for key, value in keys.items():
            assert value != defaults[section][key], f"{name}: {section}.{key} equals the default"


def test_every_param_field_has_help_and_a_valid_default() -> None:
    for key, f, _ in leaves(DetectParams):
        assert f.metadata.get("help"), f"{key} has no help"
    # The defaults themselves pass the loader's checks (each one set by --set).
    cfg = DetectParams()
    overrides = []
    for key, _, _ in leaves(DetectParams):
        value: Any = cfg
        for part in key.split("."):
            value = getattr(value, part)
        value = list(value) if isinstance(value, tuple) else value
        overrides.append(f"{key}={json.dumps(value)}")
    assert load_config(None, overrides) == cfg


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            "objects:\n  k: !!python/object:os.system x\n",
            "objects.k: cannot read 'x' tagged !!python/object:os.system (tag not supported)",
        ),
        ("objects:\n  k: !foo 3\n", "objects.k: cannot read '3' tagged !foo (tag not supported)"),
        (
            "objects:\n  k: !!int abc\n",
            "objects.k: cannot read 'abc' tagged !!int (invalid literal for int() with base 10: 'abc')",
        ),
        (
            "objects:\n  seed: 2001-12-14\n",
            "objects.seed: expected an integer, got 2001-12-14 (a date)",
        ),
        (
            "objects: !foo\n  k: 3\n",
            "objects: expected a section (a mapping of keys), got a mapping tagged !foo",
        ),
        (
            "surfaces:\n  plane_voxel: !!set {a, b, c}\n",
            "surfaces.plane_voxel: expected a list of 3 numbers, got a mapping tagged !!set",
        ),
    ],
)
def test_tags_beyond_plain_yaml_are_rejected(tmp_path: Path, body: str, message: str) -> None:
    path = write(tmp_path, body)
    line = 1 if body.startswith("objects: !") else 2
    assert config_error(path) == f"{path}:{line}: {message}"


def test_aliases_are_followed_without_expansion(tmp_path: Path) -> None:
    path = write(
        tmp_path, "surfaces:\n  plane_voxel: &v [0.2, 0.2, 0.1]\ngravity:\n  up_hint: *v\n"
    )
    cfg = load_config(path)
    assert cfg.surfaces.plane_voxel == cfg.gravity.up_hint == (0.2, 0.2, 0.1)


def test_removed_normals_section_names_its_replacement(tmp_path: Path) -> None:
    """normals.k was read by nothing; a file that still sets it is told what to use."""
    path = write(tmp_path, "normals:\n  k: 20\n")
    assert config_error(path) == (
        f"{path}:1: key 'normals' was removed in 0.2: use surfaces.normal_filter_k and "
        "surfaces.clutter_normal_k"
    )
    with pytest.raises(
        ConfigError, match=r"normals\.k=20: key 'normals' was removed in 0\.2: use surfaces"
    ):
        load_config(None, ["normals.k=20"])
