"""The README and the generated docs say what the code does: every command in the README parses,
every link resolves, the Python snippet names real API, and each generated block in docs/ names
a bench script that can write it (the numbers themselves are the scripts' business)."""

from __future__ import annotations

import inspect
import re
import shlex
from pathlib import Path

import pytest

from supportnode.cli import COMMANDS, build_parser

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
DOCS = ROOT / "docs"
BLOCK = re.compile(r"<!-- ([\w.-]+): begin -->(.*?)<!-- \1: end -->", re.S)


def _code_blocks(text: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def _readme_commands() -> list[list[str]]:
    """Each `supportnode ...` invocation in the README's shell blocks, as argv after the name."""
    commands = []
    for block in _code_blocks(README.read_text(encoding="utf-8"), "sh"):
        for line in block.splitlines():
            for part in re.split(r"&&|;|\|", line.split("#", 1)[0]):
                words = shlex.split(part)
                for i, w in enumerate(words):
                    if w.endswith("supportnode") and not w.endswith("pip"):
                        commands.append(words[i + 1 :])
                        break
    return commands


def test_readme_is_a_users_guide_not_a_notebook() -> None:
    size = len(README.read_bytes())
    assert size <= 10 * 1024, f"README.md is {size} bytes; details belong in docs/"


def test_readme_has_the_two_quick_start_commands() -> None:
    blocks = _code_blocks(README.read_text(encoding="utf-8"), "sh")
    starts = [b for b in blocks if b.startswith("python3 -m venv .venv")]
    assert any("supportnode launch" in b for b in starts)
    assert any("-m pytest" in b and ".[test]" in b for b in starts)


@pytest.mark.parametrize("argv", _readme_commands(), ids=lambda a: " ".join(a)[:60])
def test_every_readme_command_parses(argv: list[str]) -> None:
    assert argv and argv[0] in COMMANDS, f"README runs an unknown command: {argv}"
    args = build_parser(argv[0]).parse_args(argv)
    assert args.command == argv[0]


def test_readme_commands_were_found() -> None:
    names = {a[0] for a in _readme_commands()}
    assert {"launch", "detect", "run"} <= names


def test_readme_links_resolve() -> None:
    text = README.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if target.startswith(("http://", "https://")):
            continue
        assert (ROOT / target).exists(), f"README links to missing {target}"


def test_readme_python_snippet_uses_real_api() -> None:
    from supportnode.client import Publisher, Subscriber

    (snippet,) = _code_blocks(README.read_text(encoding="utf-8"), "python")
    compile(snippet, "README.md", "exec")
    for name in re.findall(r"\.(\w+)\(", snippet):
        assert hasattr(Publisher, name) or hasattr(Subscriber, name), name
    for kw in re.findall(r"publish_cloud\([^)]*?(\w+)=", snippet):
        assert kw in inspect.signature(Publisher.publish_cloud).parameters


def _generated_blocks() -> list[tuple[str, str, str]]:
    found = []
    for doc in sorted(DOCS.glob("*.md")):
        for name, body in BLOCK.findall(doc.read_text(encoding="utf-8")):
            found.append((doc.name, name, body))
    return found


@pytest.mark.parametrize("doc,name,body", _generated_blocks(), ids=lambda v: str(v)[:40])
def test_generated_block_names_its_generator(doc: str, name: str, body: str) -> None:
    # A script's second table is its block "script.variant" (real_accuracy.decimate2).
    gen = name.split(".")[0]
    script = ROOT / "bench" / f"{gen}.py"
    assert script.exists(), f"docs/{doc}: block {name!r} has no bench/{gen}.py"
    assert "--docs" in script.read_text(encoding="utf-8"), f"bench/{gen}.py cannot write docs"
    assert f"python bench/{gen}.py" in body, f"docs/{doc}: block {name!r} does not give its command"
    assert "load" in body, f"docs/{doc}: block {name!r} does not give the host load"
