"""The node's rehearsal before its first scan: what it detects, what it leaves alone."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from supportnode.node.core import NodeCore
from supportnode.node.node import Node
from supportnode.node.rehearsal import rehearsal_scan
from supportnode.params import DetectParams


def test_the_rehearsal_scan_walks_surfaces_and_objects():
    scan = rehearsal_scan()
    assert scan.pose is not None and np.isfinite(scan.points).all()
    core = NodeCore(DetectParams())
    out = core.detect(core.ingest(scan))
    heights = sorted(round(s.height, 2) for s in out.surfaces.surfaces)
    # floor, seat and table, each within the rehearsal's 2 mm of noise
    assert len(heights) == 3
    assert np.allclose(heights, [0.0, 0.45, 0.75], atol=0.02)
    table = [s.id for s in out.surfaces.surfaces if abs(s.height - 0.75) < 0.02]
    on_table = [c for c in out.obstacles.clusters if c.surface_id in table]
    assert on_table, "the boxes on the table must be objects"


def test_a_warmed_node_starts_as_a_fresh_one():
    cloud = rehearsal_scan(seed=3)
    with Node() as cold, Node() as warm:
        warm._warm()
        assert len(warm.map) == 0 and warm.core.last_stamp is None
        assert all(v == 0 for v in warm.counters.values())
        a, b = cold.process(cloud), warm.process(cloud)
    assert b.surfaces.seq == a.surfaces.seq == 1
    assert [s.id for s in b.surfaces.surfaces] == [s.id for s in a.surfaces.surfaces]
    assert [c.id for c in b.obstacles.clusters] == [c.id for c in a.obstacles.clusters]


_FIRST_SCAN = """
import json, sys
from numba.core.registry import CPUDispatcher
from supportnode.kernels import runtime
from supportnode.node.node import Node
from supportnode.node.rehearsal import rehearsal_scan

def compiled():
    # every kernel's specialisations: a new one on the first scan is a compile or cache load
    return {(m, k, str(s)) for m, mod in list(sys.modules.items())
            if m.startswith("supportnode.kernels.")
            for k, v in vars(mod).items() if isinstance(v, CPUDispatcher)
            for s in v.signatures}

with Node() as node:
    node._warm()
    before = {m for m in sys.modules if m.startswith("supportnode.kernels.")}
    kernels = compiled()
    node.process(rehearsal_scan(seed=5))
    after = {m for m in sys.modules if m.startswith("supportnode.kernels.")}
print(json.dumps({"new": sorted(after - before),
                  "specialised": sorted(f"{m}.{k}" for m, k, _ in compiled() - kernels),
                  "unwarmed": len([f for f in runtime._WARMERS if f not in runtime._WARMED])}))
"""


def test_the_first_scan_after_the_warm_up_loads_no_kernel():
    # In a fresh interpreter: this one has imported every kernel module already.
    run = subprocess.run(
        [sys.executable, "-c", _FIRST_SCAN], capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got == {"new": [], "specialised": [], "unwarmed": 0}


def test_a_failing_rehearsal_is_one_warning_not_the_end(monkeypatch, caplog):
    from supportnode.map import store

    def broken(self, *a, **kw):
        raise RuntimeError("map bug")

    monkeypatch.setattr(store.VoxelMap, "merge", broken)
    from supportnode.node.rehearsal import rehearse

    with caplog.at_level("WARNING", logger="supportnode.node"):
        took = rehearse(DetectParams())
    assert took >= 0.0
    lines = [r.getMessage() for r in caplog.records]
    assert lines == ["rehearsal detection failed: RuntimeError('map bug')"]
