"""Open vessels: a cup (a mug's body) and a bowl, each a wall of `thickness` seen outside,
inside and on its rim, with a flat bottom (frames and ray conventions: see the package).

Both are solids of revolution about z spanning z in [-height/2, height/2], open at the top.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from supportnode.sim.primitives.base import (
    Face,
    disc_hit,
    disc_sampler,
    nearest_positive,
    pick,
    quiet,
    side_hits,
    side_sampler,
    sphere_hits,
    unit,
    zone_sampler,
)

_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Cup:
    """An open cylindrical shell with a bottom, as a mug or a can without its lid: outer
    `radius`, `height`, wall and bottom `thickness`, metres."""

    radius: float
    height: float
    thickness: float
    kind: str = "cup"

    def __post_init__(self) -> None:
        if not 0 < self.thickness < min(self.radius, self.height):
            raise ValueError("thickness must be positive and less than the radius and height")

    @property
    def inner(self) -> float:
        return self.radius - self.thickness

    @property
    def floor(self) -> float:
        """z of the inside bottom, metres."""
        return -self.height / 2.0 + self.thickness

    @property
    def bounding_radius(self) -> float:
        return float(np.hypot(self.radius, self.height / 2.0))

    @property
    def half_extent(self) -> np.ndarray:
        """(3,) half sizes of the shape-frame box around the shape, metres."""
        return np.array([self.radius, self.radius, self.height / 2.0])

    def contains(self, p: np.ndarray, eps: float) -> np.ndarray:
        """(N,) bool: shape-frame points (N, 3) in the wall or the bottom, grown by eps."""
        r2 = p[:, 0] ** 2 + p[:, 1] ** 2
        h2 = self.height / 2.0
        solid = (r2 <= (self.radius + eps) ** 2) & (np.abs(p[:, 2]) <= h2 + eps)
        cavity = (r2 < max(self.inner - eps, 0.0) ** 2) & (p[:, 2] > self.floor + eps)
        return solid & ~cavity

    @quiet
    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h2 = self.height / 2.0
        t = nearest_positive(
            *side_hits(o, d, self.radius, -h2, h2),
            *side_hits(o, d, self.inner, self.floor, h2),
            disc_hit(o, d, h2, self.radius, self.inner),  # rim
            disc_hit(o, d, -h2, self.radius),  # bottom, outside
            disc_hit(o, d, self.floor, self.inner),  # bottom, inside
        )
        return t, np.zeros(t.shape, bool)

    def faces(self) -> list[Face]:
        r, ri, h2, floor = self.radius, self.inner, self.height / 2.0, self.floor
        return [
            Face(2.0 * np.pi * r * self.height, False, side_sampler(r, -h2, h2)),
            Face(2.0 * np.pi * ri * (h2 - floor), False, side_sampler(ri, floor, h2)),
            Face(np.pi * (r * r - ri * ri), False, disc_sampler(h2, r, ri)),
            Face(np.pi * r * r, False, disc_sampler(-h2, r), bottom=True),
            Face(np.pi * ri * ri, False, disc_sampler(floor, ri)),
        ]

    def normals(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) outward unit normals (out of the material) at shape-frame surface points."""
        rho = np.hypot(p[:, 0], p[:, 1])
        h2, z = self.height / 2.0, p[:, 2]
        radial = unit(p * [1.0, 1.0, 0.0])
        up = np.broadcast_to(_UP, p.shape)
        inside = rho < self.inner + self.thickness / 2.0
        dist = [
            np.where(inside, np.inf, np.abs(rho - self.radius)),
            np.where(inside & (z > self.floor), np.abs(rho - self.inner), np.inf),
            np.abs(z - h2),
            np.abs(z + h2),
            np.where(inside, np.abs(z - self.floor), np.inf),
        ]
        return pick(dist, [radial, -radial, up, -up, up])


@dataclass(frozen=True)
class Bowl:
    """A bowl: the zone of a sphere between a flat base and the rim, as a shell of `thickness`.

    `radius` is the rim's outer radius, `base_radius` the flat base's, `height` from base to
    rim (metres). The sphere through both circles has its centre on the axis at zc (shape
    frame); the inside is the concentric sphere of radius R - thickness above an inside bottom
    at -height/2 + thickness.
    """

    radius: float
    height: float
    thickness: float
    base_radius: float
    kind: str = "bowl"

    def __post_init__(self) -> None:
        if not 0 < self.base_radius < self.radius:
            raise ValueError("base_radius must be positive and less than the radius")
        if not 0 < self.thickness < self.height:
            raise ValueError("thickness must be positive and less than the height")
        ri = self.sphere_radius - self.thickness
        if ri <= abs(self.height / 2.0 - self.zc) or ri <= abs(self.floor - self.zc):
            raise ValueError("the wall is too thick for this radius and height")

    @property
    def zc(self) -> float:
        """z of the sphere's centre in the shape frame, metres."""
        return (self.radius**2 - self.base_radius**2) / (2.0 * self.height)

    @property
    def sphere_radius(self) -> float:
        return math.hypot(self.radius, self.height / 2.0 - self.zc)

    @property
    def floor(self) -> float:
        """z of the inside bottom, metres."""
        return -self.height / 2.0 + self.thickness

    def _inner_at(self, z: float) -> float:
        ri = self.sphere_radius - self.thickness
        return math.sqrt(ri * ri - (z - self.zc) ** 2)

    @property
    def widest(self) -> float:
        """The largest outer radius, metres (at the sphere's equator when it lies in the zone)."""
        inside = -self.height / 2.0 <= self.zc <= self.height / 2.0
        return self.sphere_radius if inside else self.radius

    @property
    def bounding_radius(self) -> float:
        h2 = self.height / 2.0
        rims = [math.hypot(self.radius, h2), math.hypot(self.base_radius, h2)]
        if -h2 <= self.zc <= h2:
            rims.append(math.hypot(self.sphere_radius, self.zc))
        return max(rims)

    @property
    def half_extent(self) -> np.ndarray:
        """(3,) half sizes of the shape-frame box around the shape, metres."""
        return np.array([self.widest, self.widest, self.height / 2.0])

    def contains(self, p: np.ndarray, eps: float) -> np.ndarray:
        """(N,) bool: shape-frame points (N, 3) in the wall or the base, grown by eps."""
        dist = np.linalg.norm(p - [0.0, 0.0, self.zc], axis=1)
        z = p[:, 2]
        solid = (dist <= self.sphere_radius + eps) & (np.abs(z) <= self.height / 2.0 + eps)
        cavity = (dist < self.sphere_radius - self.thickness - eps) & (z > self.floor + eps)
        return solid & ~cavity

    @quiet
    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h2, zc, r_out = self.height / 2.0, self.zc, self.sphere_radius
        t = nearest_positive(
            *sphere_hits(o, d, r_out, zc, -h2, h2),
            *sphere_hits(o, d, r_out - self.thickness, zc, self.floor, h2),
            disc_hit(o, d, h2, self.radius, self._inner_at(h2)),  # rim
            disc_hit(o, d, -h2, self.base_radius),  # base, outside
            disc_hit(o, d, self.floor, self._inner_at(self.floor)),  # bottom, inside
        )
        return t, np.zeros(t.shape, bool)

    def faces(self) -> list[Face]:
        h2, zc, floor = self.height / 2.0, self.zc, self.floor
        r_out = self.sphere_radius
        r_in = r_out - self.thickness
        rim_in, floor_r = self._inner_at(h2), self._inner_at(floor)
        return [
            # A zone's area is 2 pi R times its height, whatever its place on the sphere.
            Face(2.0 * np.pi * r_out * self.height, False, zone_sampler(r_out, zc, -h2, h2)),
            Face(2.0 * np.pi * r_in * (h2 - floor), False, zone_sampler(r_in, zc, floor, h2)),
            Face(
                np.pi * (self.radius**2 - rim_in**2), False, disc_sampler(h2, self.radius, rim_in)
            ),
            Face(
                np.pi * self.base_radius**2, False, disc_sampler(-h2, self.base_radius), bottom=True
            ),
            Face(np.pi * floor_r**2, False, disc_sampler(floor, floor_r)),
        ]

    def normals(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) outward unit normals (out of the material) at shape-frame surface points."""
        h2, z = self.height / 2.0, p[:, 2]
        rel = p - [0.0, 0.0, self.zc]
        dist = np.linalg.norm(rel, axis=1)
        radial = unit(rel)
        up = np.broadcast_to(_UP, p.shape)
        r_out, r_in = self.sphere_radius, self.sphere_radius - self.thickness
        inside = dist < r_out - self.thickness / 2.0
        gaps = [
            np.where(inside, np.inf, np.abs(dist - r_out)),
            np.where(inside & (z > self.floor), np.abs(dist - r_in), np.inf),
            np.abs(z - h2),
            np.abs(z + h2),
            np.where(inside, np.abs(z - self.floor), np.inf),
        ]
        return pick(gaps, [radial, -radial, up, -up, up])
