"""Shared test helpers: synthetic scenes built in the test, never files from outside the repo."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
REAL_SCANS = REPO.parent / "shared" / "real_scans"


def run_cli(*args: str, cwd: Path = REPO, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """``python -m supportnode ARGS`` as a user runs it: a subprocess, output captured."""
    return subprocess.run(
        [sys.executable, "-m", "supportnode", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
    )


def plane_points(rng, x0, x1, y0, y1, z, n):
    """(n, 3) points spread uniformly on the horizontal rectangle at height z."""
    return np.c_[rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), np.full(n, float(z))]


def box_points(rng, center, size, n):
    """(n, 3) points on the faces of an axis-aligned box, without the bottom face: a box
    standing on something shows no bottom to any sensor."""
    p = rng.uniform(-0.5, 0.5, (n, 3))
    axis = rng.integers(0, 3, n)
    rows = np.arange(n)
    side = np.where(p[rows, axis] < 0, -0.5, 0.5)
    side[axis == 2] = 0.5
    p[rows, axis] = side
    return np.asarray(center) + p * np.asarray(size)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture
def room(rng):
    """Floor 4x4 m at z=0, a 1.0 x 0.7 m table top at 0.73 m on four legs, a box on the table,
    a wall. Returns (points, truth) where truth is 0 floor, 1 table, 2 box, 3 wall, 4 legs."""
    parts = [
        plane_points(rng, -2.03, 2.01, -2.02, 2.05, 0.0, 60000),
        plane_points(rng, -0.53, 0.47, -0.31, 0.39, 0.73, 12000),
        box_points(rng, (0.0, 0.0, 0.83), (0.2, 0.2, 0.2), 3000),
        np.c_[rng.uniform(-2, 2, 8000), np.full(8000, 2.05), rng.uniform(0, 2, 8000)],
    ]
    legs = []
    for x, y in ((-0.5, -0.28), (-0.5, 0.36), (0.44, -0.28), (0.44, 0.36)):
        t = rng.uniform(0, 2 * np.pi, 600)
        legs.append(np.c_[x + 0.02 * np.cos(t), y + 0.02 * np.sin(t), rng.uniform(0, 0.72, 600)])
    parts.append(np.vstack(legs))
    truth = np.concatenate([np.full(len(p), i) for i, p in enumerate(parts)])
    return np.vstack(parts), truth


@pytest.fixture
def real_scans():
    if not REAL_SCANS.is_dir():
        pytest.skip("../shared/real_scans is not beside the repo")
    return REAL_SCANS
