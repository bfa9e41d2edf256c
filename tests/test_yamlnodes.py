"""The one line-aware YAML loader: every problem one line naming file:line."""

from __future__ import annotations

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.errors import ConfigError, SceneError
from supportnode.yamlnodes import LineMap, LineSeq, compose, line_tree, read_text


def tree(text: str, error: type = SceneError):
    return line_tree(compose(text, "f.yaml", error), "f.yaml", error)


def test_values_remember_their_lines():
    doc = tree("a: 1\nb:\n  - x\n  - {c: 2.5}\n")
    assert isinstance(doc, LineMap) and doc == {"a": 1, "b": ["x", {"c": 2.5}]}
    assert doc.line == 1 and doc.key_lines == {"a": 1, "b": 2}
    seq = doc["b"]
    assert isinstance(seq, LineSeq) and seq.line == 3 and seq.item_lines == [3, 4]
    assert seq[1].key_lines == {"c": 4}


def test_merge_keys_and_anchors_expand():
    doc = tree("base: &b {x: 1, y: 2}\nitem:\n  <<: *b\n  y: 3\n")
    assert doc["item"] == {"x": 1, "y": 3}  # the item's own key wins
    with pytest.raises(SceneError, match=r"f\.yaml:5: duplicate key 'y'"):
        tree("base: &b {x: 1, y: 2}\nitem:\n  <<: *b\n  y: 3\n  y: 4\n")


def test_empty_text_is_none():
    assert tree("# only a comment\n") is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("a: 1\na: 2\n", "f.yaml:2: duplicate key 'a'"),
        ("a: [1, 2\n", "f.yaml:2: YAML syntax error: "),
        ("a: !!python/object:os.system x\n", "f.yaml:1: cannot read 'x' tagged !!python/"),
        ("a: !!int abc\n", "f.yaml:1: cannot read 'abc' tagged !!int (invalid literal"),
        ("? [1, 2]\n: x\n", "f.yaml:1: a key must be a scalar, got a list of 2 items"),
        ("a: 1\n---\nb: 2\n", "f.yaml:2: YAML syntax error: "),
    ],
)
def test_problems_are_one_line_with_the_callers_error(text, message):
    with pytest.raises(ConfigError) as err:
        tree(text, ConfigError)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_read_text_names_the_file(tmp_path):
    with pytest.raises(SceneError, match=r"nope\.yaml: no such file$"):
        read_text(tmp_path / "nope.yaml", SceneError)
    with pytest.raises(ConfigError, match="is a directory"):
        read_text(tmp_path, ConfigError)
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes(b"a: \xe9\n")
    with pytest.raises(ConfigError, match=r"latin1\.yaml: not UTF-8 text \(invalid"):
        read_text(bad, ConfigError)
    good = tmp_path / "ok.yaml"
    good.write_text("a: é\n", encoding="utf-8")
    assert read_text(good, ConfigError) == "a: é\n"


_scalars = (
    st.none()
    | st.booleans()
    | st.integers(-(10**12), 10**12)
    | st.floats(allow_nan=False, width=64)
    | st.text(max_size=12)
)
_keys = st.text(max_size=8) | st.integers(-100, 100)
_docs = st.recursive(
    _scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_keys, inner, max_size=4),
    max_leaves=20,
)


@settings(max_examples=150, deadline=None)
@given(_docs, st.booleans())
def test_same_values_as_safe_load(doc, flow):
    # The reference: PyYAML's own safe_load of the same text, block and flow style.
    text = yaml.safe_dump(doc, default_flow_style=flow, allow_unicode=True)
    assert tree(text) == yaml.safe_load(text)
