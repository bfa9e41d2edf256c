"""What a fresh ``supportnode detect`` process loads before it reads its cloud (issue 20: the
command's wall time on a 150k-point cloud, most of it imports and compiled-kernel loads)."""

from __future__ import annotations

import json
import subprocess
import sys

_DETECT = ("supportnode.cli.detect", "supportnode.pipeline", "supportnode.io.results")


def _loaded_after(*modules: str) -> set[str]:
    """Every module a fresh interpreter holds after importing ``modules``."""
    code = f"import sys, json; import {', '.join(modules)}; print(json.dumps(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_detect_imports_the_kernels_of_some_clouds_only_when_they_come():
    # `runtime.warm` loads every imported kernel module's kernels (a few ms each): those of
    # depth cameras' surface bands and faces, and of alignment, wait for a cloud that needs them
    loaded = _loaded_after(*_DETECT)
    on_demand = {f"supportnode.kernels.{m}" for m in ("band", "cellgraph", "rotate", "windows")}
    assert not on_demand & loaded


def test_detect_imports_no_ndimage_nor_csgraph():
    # scipy.spatial stays (Qhull's volumes, k-d trees); the rasters' transforms and morphology
    # are compiled (`kernels.morphology`) and csgraph is imported by its rare users
    loaded = _loaded_after(*_DETECT)
    assert not {m for m in loaded if m.startswith(("scipy.ndimage", "scipy.sparse.csgraph"))}
