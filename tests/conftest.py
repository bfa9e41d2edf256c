"""Shared test helpers: synthetic scenes built in the test, never files from outside the repo."""

from __future__ import annotations

import contextlib
import dataclasses
import shutil
import socket
import subprocess
import sys
import threading
import time
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


def table_legs(rng, corners, top, n=600):
    """(len(corners) * n, 3) points on round legs (2 cm radius) from the floor up to ``top``."""
    legs = []
    for x, y in corners:
        t = rng.uniform(0, 2 * np.pi, n)
        legs.append(np.c_[x + 0.02 * np.cos(t), y + 0.02 * np.sin(t), rng.uniform(0, top, n)])
    return np.vstack(legs)


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


def free_port() -> int:
    """A TCP port of 127.0.0.1 free now (another process may take it before it is used)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def node_keys(tmp_path: Path) -> dict[str, Path]:
    """CURVE key pairs (node, driver, client, stranger) in ``made``; the node's key folder in
    its layout (supportnode.curve): the node's pair, the driver as scan server, the client in
    subscribers/, the driver in drivers/; ``trusts_node``: a binding driver's authorised
    clients (the node's public key)."""
    import zmq.auth

    made = tmp_path / "made"
    made.mkdir()
    for name in ("node", "driver", "client", "stranger"):
        zmq.auth.create_certificates(made, name)
    folder = tmp_path / "node"
    for sub in ("subscribers", "drivers"):
        (folder / sub).mkdir(parents=True)
    shutil.copy(made / "node.key_secret", folder / "server.key_secret")
    shutil.copy(made / "driver.key", folder / "scan_server.key")
    shutil.copy(made / "client.key", folder / "subscribers" / "client.key")
    shutil.copy(made / "driver.key", folder / "drivers" / "driver.key")
    trusts_node = tmp_path / "trusts_node"
    trusts_node.mkdir()
    shutil.copy(made / "node.key", trusts_node / "node.key")
    return {"made": made, "folder": folder, "trusts_node": trusts_node}


@contextlib.contextmanager
def spinning_node(**node_keys):
    """A `Node` spinning in a thread over real sockets (``node.*`` keys overridden; by default
    no map messages, diagnostics every 0.2 s): yields (node,
    its thread) once it is ready (kernels warmed: on an empty numba cache the first node of a
    session compiles them, ~25 s on two cores, and publishes nothing meanwhile); stops it on exit."""
    from supportnode.node.node import Node
    from supportnode.params import DetectParams

    keys = {"map_period": 0.0, "diagnostics_period": 0.2, **node_keys}
    p = DetectParams()
    with Node(dataclasses.replace(p, node=dataclasses.replace(p.node, **keys))) as node:
        node.open()
        th = threading.Thread(target=node.spin, kwargs={"handle_signals": False}, daemon=True)
        th.start()
        end = time.monotonic() + 180.0
        while not node._ready and th.is_alive() and time.monotonic() < end:
            time.sleep(0.05)
        try:
            yield node, th
        finally:
            node.stop()
            th.join(10)
