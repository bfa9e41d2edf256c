"""A fresh install's kernels compiled in child processes: when, what, and what a failure costs."""

import logging
import os
import subprocess
import sys
import time
from pathlib import Path

from supportnode.kernels import precompile, runtime

KERNELS = Path(precompile.__file__).parent


def _child(args: list[str], cache: Path, stdin: str = "") -> subprocess.CompletedProcess:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    cmd = [sys.executable, "-m", "supportnode.kernels.precompile", *args]
    return subprocess.run(cmd, input=stdin, capture_output=True, text=True, env=env, timeout=300)


def _indexed(cache: Path) -> set[str]:
    """Kernel modules with at least one index file in numba's cache under ``cache``."""
    return {p.name.split(".")[0] for p in cache.rglob("*.nbi")}


def test_kernel_modules_are_every_kernel_file_but_the_runtime():
    files = {p.stem for p in KERNELS.glob("*.py")} - {
        "__init__",
        "runtime",
        "precompile",
        "loading",
    }
    assert precompile.kernel_modules() == sorted(files)
    assert "voxelstore" in files and "band" in files


def test_modules_go_heaviest_first():
    names = precompile._by_weight(["rects", "knn", "offsets"])
    assert names == ["knn", "rects", "offsets"]  # 12 kB, 3 kB, 0.7 kB of source


def test_a_child_compiles_each_module_named_on_stdin_and_answers_with_its_name(tmp_path):
    done = _child([], tmp_path, "rects\nneighbourhoods\n")
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["rects", "neighbourhoods"]
    indexed = _indexed(tmp_path)
    assert any(i.startswith("rects") for i in indexed)
    assert any(i.startswith("neighbourhoods") for i in indexed)


def test_a_child_refuses_an_unknown_module_in_one_line(tmp_path):
    done = _child(["rects", "no_such_kernels"], tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == "precompile: no kernel module 'no_such_kernels'"


def test_an_empty_cache_counts_the_imported_modules_kernels_as_cold(tmp_path):
    code = (
        "import supportnode.kernels.rects, supportnode.kernels.knn\n"
        "from supportnode.kernels import precompile\n"
        "print(sorted(precompile.cold_kernels(precompile.kernel_modules())))"
    )
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "['knn', 'rects']"  # imported ones only; nothing compiled


def test_a_warm_cache_starts_no_child(monkeypatch):
    runtime.warm(["rects", "neighbourhoods"])  # this process's cache now holds them
    assert precompile.cold_kernels(["rects", "neighbourhoods"]) == {}

    def no_child(*a, **k):
        raise AssertionError("a child was started")

    monkeypatch.setattr(subprocess, "Popen", no_child)
    # Only modules known warm here: others may be half compiled by the tests before.
    monkeypatch.setattr(precompile, "kernel_modules", lambda: ["rects", "neighbourhoods"])
    assert precompile.compile_cold(workers=2) == 0


def test_switched_off_or_one_core_starts_no_child(monkeypatch):
    monkeypatch.setattr(precompile, "cold_kernels", lambda names: {"knn": 9, "rects": 1})
    monkeypatch.setenv("SUPPORTNODE_PRECOMPILE", "0")
    assert precompile.compile_cold(workers=2) == 0
    monkeypatch.delenv("SUPPORTNODE_PRECOMPILE")
    assert precompile.compile_cold(workers=1) == 0
    assert precompile.compile_cold(workers=0) == 0


def test_a_bad_switch_value_is_one_warning_and_no_child(monkeypatch, caplog):
    monkeypatch.setattr(precompile, "cold_kernels", lambda names: {"knn": 9, "rects": 1})
    monkeypatch.setenv("SUPPORTNODE_PRECOMPILE", "off")
    with caplog.at_level(logging.WARNING, logger="supportnode.kernels"):
        assert precompile.compile_cold(workers=2) == 0
    assert [r.getMessage() for r in caplog.records] == [
        "SUPPORTNODE_PRECOMPILE='off': expected 0 or 1; compiling in this process"
    ]


def test_a_cold_cache_is_compiled_by_children_taking_modules_in_turn(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(precompile, "kernel_modules", lambda: ["rects", "neighbourhoods"])
    monkeypatch.setattr(precompile, "cold_kernels", lambda names: {"knn": 9, "rects": 1})
    assert precompile.compile_cold(workers=4) == 2  # no more children than modules
    indexed = _indexed(tmp_path)
    assert any(i.startswith("rects") for i in indexed)
    assert any(i.startswith("neighbourhoods") for i in indexed)


def test_a_failing_child_is_one_warning_and_the_caller_goes_on(monkeypatch, tmp_path, caplog):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(precompile, "kernel_modules", lambda: ["no_such_kernels", "offsets"])
    monkeypatch.setattr(precompile, "cold_kernels", lambda names: {"knn": 9, "rects": 1})
    with caplog.at_level(logging.WARNING, logger="supportnode.kernels"):
        assert precompile.compile_cold(workers=2) == 2
    failed = [r.getMessage() for r in caplog.records if "failed" in r.getMessage()]
    assert failed == [
        "a child compiling kernels failed (exit 2): precompile: no kernel module"
        " 'no_such_kernels'; the rest compile here"
    ]


def test_a_hanging_child_is_killed_at_the_deadline(monkeypatch, caplog):
    monkeypatch.setattr(precompile, "_DEADLINE_S", 0.5)
    monkeypatch.setattr(precompile, "kernel_modules", lambda: ["rects", "offsets"])
    monkeypatch.setattr(precompile, "cold_kernels", lambda names: {"knn": 9, "rects": 1})
    hang = [sys.executable, "-c", "import time; time.sleep(60)"]
    monkeypatch.setattr(precompile, "_command", lambda: hang)
    t = time.monotonic()
    with caplog.at_level(logging.WARNING, logger="supportnode.kernels"):
        assert precompile.compile_cold(workers=2) == 2
    assert time.monotonic() - t < 30
    killed = "a child compiling kernels failed (exit -9): no message; the rest compile here"
    assert [r.getMessage() for r in caplog.records] == [killed, killed]


def test_warm_looks_for_a_cold_cache_once_per_process(monkeypatch):
    calls = []
    monkeypatch.setattr(runtime, "_precompile_tried", False)
    monkeypatch.setattr(precompile, "compile_cold", lambda workers: calls.append(workers))
    runtime.warm()
    runtime.warm()
    assert calls == [runtime._threads]
