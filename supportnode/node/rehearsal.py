"""A rehearsal detection before the node subscribes: one synthetic scan through a scratch core.

Warming the kernels (`kernels.runtime.warm`) compiles or loads the kernel modules imported so
far; the detection imports several more on its first call, and its first call of each numpy
and scipy path pays once too. A live node's first scan paid all of it (90 ms against 60 in
process, 136 against 58 over sockets). One scan of a small room, a table and two touching
boxes through a throwaway `NodeCore` with the node's configuration walks those paths; the
node's own map, ids and counters never see it. Pure (numpy in, numbers out).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from supportnode.msgs import PointCloud
from supportnode.params import DetectParams

__all__ = ["rehearsal_scan", "rehearse", "warm_up"]

_SENSOR_HEIGHT = 1.4  # m above the floor
# Kernel modules the detection imports when a cloud needs them, not with its own modules.
_ON_DEMAND = ("band", "cellgraph")


def _plane(rng: np.random.Generator, lo: tuple, hi: tuple, z: float, n: int) -> np.ndarray:
    """n points uniform in the x, y box [lo, hi] at height z (metres)."""
    xy = rng.uniform(lo, hi, size=(n, 2))
    return np.column_stack([xy, np.full(n, z)])


def _box(rng: np.random.Generator, lo: tuple, hi: tuple, n: int) -> np.ndarray:
    """n points on the top and the four sides of the axis-aligned box [lo, hi] (3,)."""
    lo_, hi_ = np.asarray(lo, float), np.asarray(hi, float)
    p = rng.uniform(lo_, hi_, size=(n, 3))
    face = rng.integers(0, 5, n)
    axis = np.array([2, 0, 0, 1, 1])[face]
    side = np.where(np.isin(face, (0, 1, 3)), hi_[axis], lo_[axis])
    p[np.arange(n), axis] = side
    return p


def rehearsal_scan(seed: int = 0) -> PointCloud:
    """A posed scan (sensor 1.4 m above a 4 x 4 m floor, z up) of a table with two touching
    boxes and a chair seat, ~40,000 points with 2 mm of noise; stamp 0, seq 1."""
    rng = np.random.default_rng(seed)
    parts = [
        _plane(rng, (-2.0, -2.0), (2.0, 2.0), 0.0, 24_000),
        _plane(rng, (0.6, -0.5), (1.6, 0.5), 0.75, 8_000),
        _plane(rng, (-1.4, -0.3), (-0.9, 0.2), 0.45, 2_000),
        _box(rng, (0.9, -0.2, 0.75), (1.1, 0.0, 0.95), 3_000),
        _box(rng, (1.1, -0.15, 0.75), (1.25, 0.05, 0.85), 2_500),
    ]
    world = np.concatenate(parts)
    world = world + rng.normal(0.0, 0.002, size=world.shape)
    sensor = np.array([0.0, 0.0, _SENSOR_HEIGHT])
    pose = (sensor, np.array([0.0, 0.0, 0.0, 1.0]))
    return PointCloud.from_xyz((world - sensor).astype(np.float32), 0.0, "sensor", 1, pose=pose)


def rehearse(params: DetectParams, map_factory: Callable | None = None) -> float:
    """Ingest and detect `rehearsal_scan` on a scratch core with ``params``; seconds taken.
    Its log lines are dropped (a rehearsal's map reset or gravity verdict is nobody's news);
    a failure is one warning, never the node's end (its scans then meet the same error, each
    counted as an internal error)."""
    from supportnode.node.core import NodeCore

    quiet = logging.getLogger("supportnode.node.rehearsal")
    quiet.propagate = False
    quiet.addHandler(logging.NullHandler())
    t = time.perf_counter()
    try:
        core = NodeCore(params, map_factory=map_factory, logger=quiet)
        job = core.ingest(rehearsal_scan())
        if job is not None:
            core.detect(job)
        core.settle()  # as the node: the clearing after the detection took its points
    except Exception as exc:  # a bug the first scan will meet too, and report
        logging.getLogger("supportnode.node").warning("rehearsal detection failed: %r", exc)
    return time.perf_counter() - t


def warm_up(params: DetectParams, threads: int | None = None) -> float:
    """Everything a node does before its first scan: the kernels' threads (``threads``: None,
    numba's default), their compilation or cache load, then `rehearse`; seconds taken. The
    kernel modules the rehearsal imported are warmed after it (their other signatures)."""
    from supportnode.kernels import runtime
    from supportnode.kernels.loading import load_lightly

    runtime.configure(threads)
    load_lightly()  # the node's process: numba's compile set-up only when it compiles
    runtime.keep_freed_memory()  # the node's process: each scan reuses the last one's pages
    # The detection imports these kernel modules only for the clouds that need them (a depth
    # camera's surface bands and object faces); a node meets any cloud: loaded before its first.
    took = runtime.warm(_ON_DEMAND) + rehearse(params)
    return took + runtime.warm()
