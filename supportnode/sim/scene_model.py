"""A scene: posed primitives with their ground-truth labels (built by `supportnode.sim.scene`
from YAML, or in code)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from supportnode.sim.cloud import ROLE_OBJECT, ROLE_STRUCTURE, ROLE_SURFACE
from supportnode.sim.primitives import Shape
from supportnode.sim.support import Support, object_support

# (8, 3) corner signs of a box, in the order Box.local_corners used.
_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


@dataclass(frozen=True)
class Primitive:
    """One posed shape with its labels.

    pose: (4, 4) float64 shape-to-world transform. role: "surface" | "structure" | "object".
    object_id / surface_id: -1 when not an object / not a surface. line: line in the scene file.
    """

    index: int
    name: str
    shape: Shape
    pose: np.ndarray
    role: str
    object_id: int
    surface_id: int
    line: int

    @property
    def kind(self) -> str:
        return self.shape.kind

    def world_aabb(self) -> np.ndarray:
        """(2, 3) float64 [min, max] world box containing the shape's frame-aligned box
        (`half_extent`: exact for boxes), metres."""
        local = _CORNERS * self.shape.half_extent
        world = local @ self.pose[:3, :3].T + self.pose[:3, 3]
        return np.stack([world.min(axis=0), world.max(axis=0)])


@dataclass(frozen=True)
class Scene:
    """A scene: primitives in file order, surface and object names indexed by id."""

    name: str
    primitives: tuple[Primitive, ...]
    surface_names: tuple[str, ...]
    object_names: tuple[str, ...]
    description: str = ""
    trajectory: dict[str, Any] = field(default_factory=dict)
    source: str = "<string>"

    def bounds(self) -> np.ndarray:
        """(2, 3) float64 [min, max] world box of all primitives, metres."""
        boxes = np.stack([p.world_aabb() for p in self.primitives])
        return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])

    @functools.cached_property
    def support(self) -> Support:
        """What holds each object up (see `supportnode.sim.support`), derived once."""
        return object_support(self)

    def label_table(self) -> dict[str, np.ndarray]:
        """Per-primitive lookup arrays, each (P,): role of the top face and of other faces
        (int8), object id and surface id of the top face, and for object parts the object's
        support: the object it stands on and the surface under it or its stack (int32, -1
        for none)."""
        code = {"surface": ROLE_SURFACE, "structure": ROLE_STRUCTURE, "object": ROLE_OBJECT}
        is_surf = np.array([p.role == "surface" for p in self.primitives])
        role = np.array([code[p.role] for p in self.primitives], np.int8)
        obj = np.array([p.object_id for p in self.primitives], np.int32)
        support = self.support
        by = np.append(support.supported_by, np.int32(-1))  # index -1: not an object
        under = np.append(support.surface, np.int32(-1))
        return {
            "role_top": role,
            "role_other": np.where(is_surf, ROLE_STRUCTURE, role).astype(np.int8),
            "object": obj,
            "surface_top": np.array([p.surface_id for p in self.primitives], np.int32),
            "supported_by": by[obj],
            "support_surface": under[obj],
        }


def rpy_matrix(rpy_deg: tuple[float, float, float] | np.ndarray) -> np.ndarray:
    """(3, 3) rotation Rz(yaw) Ry(pitch) Rx(roll) from (roll, pitch, yaw) in degrees."""
    r, p, y = np.radians(np.asarray(rpy_deg, np.float64))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def pose_matrix(xyz: Any = (0, 0, 0), rpy_deg: Any = (0, 0, 0)) -> np.ndarray:
    """(4, 4) float64 transform from translation (metres) and roll/pitch/yaw (degrees)."""
    t = np.eye(4)
    t[:3, :3] = rpy_matrix(rpy_deg)
    t[:3, 3] = xyz
    return t
