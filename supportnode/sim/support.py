"""What holds each object up, derived from a scene's geometry: the surface under it (or under
its stack) and the object it stands on.

An object stands on whatever lies within SUPPORT_GAP below its lowest points (sampled on its
faces, bottoms included): the majority of those points decides between a surface, another
object and structure. Stacks resolve downwards, so a box on a box on a table has the table as
its surface. An object with nothing below (hung, wedged) stands on nothing: -1 and -1.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from supportnode.sim.cloud import rotate

if TYPE_CHECKING:
    from supportnode.sim.scene_model import Primitive, Scene

SUPPORT_GAP = 0.005  # metres: a gap this small below an object is contact (a sensor's few mm)
_LOWEST = 0.002  # metres: points this close to an object's lowest are its feet
_PROBES = np.arange(1, 6) * 1e-3  # metres below each foot point, nearest first
_FOOT_SAMPLES = 4000  # points drawn over each object's faces to find its feet


@dataclass(frozen=True)
class Support:
    """Per object id, (O,) int32 each: `surface`, the surface under the object or under its
    stack (-1: none); `supported_by`, the object it stands on (-1: a surface, or nothing)."""

    surface: np.ndarray
    supported_by: np.ndarray


def object_support(scene: Scene) -> Support:
    """The support of every object of `scene` (deterministic: its own fixed draws)."""
    n = len(scene.object_names)
    direct = [_stands_on(scene, o) for o in range(n)]
    supported_by = np.array([obj for obj, _ in direct], np.int32)
    surface = np.full(n, -1, np.int32)
    for o in range(n):
        seen, k = {o}, o
        while supported_by[k] >= 0 and supported_by[k] not in seen:  # down the stack
            k = int(supported_by[k])
            seen.add(k)
        surface[o] = direct[k][1] if supported_by[k] < 0 else -1
    return Support(surface, supported_by)


def _stands_on(scene: Scene, object_id: int) -> tuple[int, int]:
    """(object below or -1, surface below or -1) for one object, by majority of its feet."""
    own = [p for p in scene.primitives if p.object_id == object_id]
    feet = _feet(own, np.random.default_rng([object_id, 7]))
    lo = feet.min(axis=0) - [0.0, 0.0, _PROBES[-1]]
    hi = feet.max(axis=0)
    others = [
        p
        for p in scene.primitives
        if p.object_id != object_id
        and np.all(p.world_aabb()[0] <= hi + 1e-4)
        and np.all(p.world_aabb()[1] >= lo - 1e-4)
    ]
    below = np.full(len(feet), -1)
    for dz in _PROBES:  # the first thing under each foot, nearest first
        open_ = np.flatnonzero(below < 0)
        probe = feet[open_] - [0.0, 0.0, dz]
        for other in others:
            local = rotate(probe - other.pose[:3, 3], other.pose[:3, :3].T)
            hit = other.shape.contains(local, 1e-4) & (below[open_] < 0)
            below[open_[hit]] = other.index
    found = below[below >= 0]
    if found.size == 0:
        return -1, -1
    best = scene.primitives[int(np.bincount(found).argmax())]
    if best.role == "object":
        return best.object_id, -1
    return -1, best.surface_id  # a surface, or structure (-1)


def _feet(prims: list[Primitive], rng: np.random.Generator) -> np.ndarray:
    """(F, 3) world points on the object's faces within _LOWEST of its lowest point."""
    faces = [(p, f) for p in prims for f in p.shape.faces()]
    area = np.array([f.area for _, f in faces])
    counts = np.maximum(np.round(_FOOT_SAMPLES * area / area.sum()).astype(int), 16)
    pts = np.concatenate(
        [
            rotate(f.sample(rng, int(c)), p.pose[:3, :3]) + p.pose[:3, 3]
            for (p, f), c in zip(faces, counts, strict=True)
        ]
    )
    return pts[pts[:, 2] <= pts[:, 2].min() + _LOWEST]
