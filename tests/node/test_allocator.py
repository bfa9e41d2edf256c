"""The node keeps freed memory for the next scan: no page faults for a repeated working set."""

from __future__ import annotations

import subprocess
import sys

import pytest

_CHURN = """
import resource, sys
import numpy as np
if sys.argv[1] == "retain":
    from supportnode.node.allocator import retain_freed_memory
    assert retain_freed_memory()
# A detection's pattern: several arrays of a few MB alive together, then all freed.
a = [np.ones(500_000) for _ in range(6)]
del a
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    a = [np.ones(500_000) for _ in range(6)]
    del a
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    out = subprocess.run(
        [sys.executable, "-c", _CHURN, mode], capture_output=True, text=True, check=True
    )
    return int(out.stdout.strip())


@pytest.mark.skipif(
    not sys.platform.startswith("linux")
    or "glibc" not in " ".join(__import__("platform").libc_ver()),
    reason="glibc only",
)
def test_freed_arrays_are_reused_without_page_faults():
    default, retained = _faults("default"), _faults("retain")
    assert default > 20 * 1000  # 20 x 24 MB faulted in again: ~6,000 pages each time
    assert retained < 200


def test_other_platforms_are_a_no_op(monkeypatch):
    from supportnode.node import allocator

    monkeypatch.setattr(allocator.sys, "platform", "darwin")
    assert allocator.retain_freed_memory() is False
