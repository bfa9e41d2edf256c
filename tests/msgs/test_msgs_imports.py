"""What a planner pays to import the client: the wire knows no geometry, scipy or numba."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

_HEAVY = ("scipy", "numba", "yaml", "supportnode.geometry", "supportnode.detection")


def _loaded_after(module: str) -> dict[str, bool]:
    """Which heavy modules a fresh interpreter holds after ``import module``."""
    code = (
        f"import sys, json; import {module}; "
        f"print(json.dumps({{m: m in sys.modules for m in {list(_HEAVY)!r}}}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("module", ["supportnode.client", "supportnode.msgs"])
def test_client_and_msgs_load_no_geometry(module):
    loaded = _loaded_after(module)
    assert not any(loaded.values()), {m for m, v in loaded.items() if v}


def test_the_check_sees_a_heavy_import():
    # The subprocess check itself must be able to fail: the pipeline loads the geometry.
    assert _loaded_after("supportnode.pipeline")["supportnode.geometry"]
