"""What a planner pays to import the client: the wire knows no geometry, scipy or numba."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

# Of the geometry, only the pose maths (numpy only) may come along: the package's __init__
# imports nothing, so loading `supportnode.geometry.transform` loads no other geometry module.
_ALLOWED = {"supportnode.geometry", "supportnode.geometry.transform"}
# cython_runtime: a module Cython's compiled extensions (pyzmq's, msgpack's) register.
_THIRD_PARTY = {"numpy", "zmq", "msgpack", "cython_runtime"}


def _loaded_after(module: str) -> set[str]:
    """Every module a fresh interpreter holds after ``import module`` (none before it)."""
    code = (
        "import sys, json; before = set(sys.modules); "
        f"import {module}; print(json.dumps(sorted(set(sys.modules) - before)))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize("module", ["supportnode.client", "supportnode.msgs"])
def test_client_and_msgs_load_numpy_pyzmq_msgpack_only(module):
    loaded = _loaded_after(module)
    heavy = {m for m in loaded if m.split(".")[0] in {"scipy", "numba", "yaml", "llvmlite"}}
    assert not heavy
    geometry = {
        m for m in loaded if m.startswith(("supportnode.geometry", "supportnode.detection"))
    }
    assert geometry <= _ALLOWED
    top = {m for m in loaded if "." not in m and not m.startswith("_")}
    # Third-party top-level packages: only the three the client documents (the rest is stdlib).
    third = {m for m in top if m not in sys.stdlib_module_names and m != "supportnode"}
    assert third <= _THIRD_PARTY, third


def test_the_check_sees_a_heavy_import():
    # The subprocess check itself must be able to fail: the pipeline loads the geometry.
    loaded = _loaded_after("supportnode.pipeline")
    assert "scipy" in loaded and "supportnode.geometry.surfaces" in loaded
