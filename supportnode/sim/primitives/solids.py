"""The closed solids: box, cylinder, sphere, cone (frames and ray conventions: see the package)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.sim.primitives.base import (
    EPS,
    Face,
    disc_hit,
    disc_sampler,
    nearest_positive,
    pick,
    quadratic_roots,
    quiet,
    unit,
)


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in its own frame, `size` (3,) metres, centred."""

    size: tuple[float, float, float]
    kind: str = "box"

    @property
    def half(self) -> np.ndarray:
        return np.asarray(self.size, np.float64) / 2.0

    @property
    def bounding_radius(self) -> float:
        return float(np.linalg.norm(self.half))

    @property
    def half_extent(self) -> np.ndarray:
        """(3,) half sizes of the shape-frame box around the shape, metres."""
        return self.half

    def normals(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) outward unit normals at shape-frame surface points p (N, 3): the face the
        point lies nearest."""
        gap = np.abs(p) - self.half  # 0 on the face of that axis, negative on the others
        axis = np.argmax(gap, axis=1)
        out = np.zeros_like(p)
        rows = np.arange(len(p))
        out[rows, axis] = np.where(p[rows, axis] >= 0, 1.0, -1.0)
        return out

    def contains(self, p: np.ndarray, eps: float) -> np.ndarray:
        """(N,) bool: shape-frame points (N, 3) inside the box grown by eps."""
        return np.all(np.abs(p) <= self.half + eps, axis=1)

    @quiet
    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Slab test: entry t (exit t when the origin is inside) and whether it is the +z face."""
        half = self.half
        t_in = np.full(len(o), -np.inf)
        t_out = np.full(len(o), np.inf)
        entry_axis = np.zeros(len(o), np.int8)
        # Per axis on 1-D columns: reductions over a short (N, 3) axis are slow in numpy.
        for axis in range(3):
            da = d[:, axis]
            # A zero direction component would give 0 * inf = NaN on the slab boundary; a tiny
            # stand-in keeps the arithmetic finite and the answer unchanged.
            inv = 1.0 / np.where(np.abs(da) < 1e-15, 1e-15, da)
            t1 = (-half[axis] - o[:, axis]) * inv
            t2 = (half[axis] - o[:, axis]) * inv
            lo = np.minimum(t1, t2)
            later = lo > t_in
            entry_axis[later] = axis
            t_in = np.where(later, lo, t_in)
            t_out = np.minimum(t_out, np.maximum(t1, t2))
        hit = t_out >= np.maximum(t_in, EPS)
        inside = t_in <= EPS
        t = np.where(hit, np.where(inside, t_out, t_in), np.inf)
        # Entering through the +z face means travelling down onto it.
        top = hit & ~inside & (entry_axis == 2) & (d[:, 2] < 0)
        return t, top

    def faces(self) -> list[Face]:
        sx, sy, sz = self.size
        half = self.half
        out = []
        for axis in range(3):
            u, v = [a for a in range(3) if a != axis]
            for sign in (-1.0, 1.0):

                def sample(
                    rng: np.random.Generator, n: int, axis=axis, u=u, v=v, sign=sign
                ) -> np.ndarray:
                    p = np.empty((n, 3))
                    p[:, axis] = sign * half[axis]
                    p[:, u] = (rng.random(n) - 0.5) * (2.0 * half[u])
                    p[:, v] = (rng.random(n) - 0.5) * (2.0 * half[v])
                    return p

                area = (sx, sy, sz)[u] * (sx, sy, sz)[v]
                out.append(
                    Face(area, axis == 2 and sign > 0, sample, bottom=axis == 2 and sign < 0)
                )
        return out


@dataclass(frozen=True)
class Cylinder:
    """Cylinder along its z axis, `radius` and `height` metres, centred."""

    radius: float
    height: float
    kind: str = "cylinder"

    @property
    def bounding_radius(self) -> float:
        return float(np.hypot(self.radius, self.height / 2.0))

    def contains(self, p: np.ndarray, eps: float) -> np.ndarray:
        """(N,) bool: shape-frame points (N, 3) inside the cylinder grown by eps."""
        r2 = p[:, 0] ** 2 + p[:, 1] ** 2
        return (r2 <= (self.radius + eps) ** 2) & (np.abs(p[:, 2]) <= self.height / 2.0 + eps)

    @property
    def half_extent(self) -> np.ndarray:
        """(3,) half sizes of the shape-frame box around the shape, metres."""
        return np.array([self.radius, self.radius, self.height / 2.0])

    def normals(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) outward unit normals at shape-frame surface points p (N, 3)."""
        rho = np.hypot(p[:, 0], p[:, 1])
        h2 = self.height / 2.0
        side = unit(p * [1.0, 1.0, 0.0])
        up = np.broadcast_to([0.0, 0.0, 1.0], p.shape)
        dist = [np.abs(rho - self.radius), np.abs(p[:, 2] - h2), np.abs(p[:, 2] + h2)]
        return pick(dist, [side, up, -up])

    @quiet
    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r, h2 = self.radius, self.height / 2.0
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]
        c = o[:, 0] ** 2 + o[:, 1] ** 2 - r * r
        sq = np.sqrt(b * b - a * c)
        sides = [(-b - sq) / a, (-b + sq) / a]
        sides = [np.where(np.abs(o[:, 2] + s * d[:, 2]) <= h2, s, np.inf) for s in sides]
        t_top = disc_hit(o, d, h2, r)
        t_bottom = disc_hit(o, d, -h2, r)
        t = nearest_positive(sides[0], sides[1], t_top, t_bottom)
        top = np.isfinite(t) & (t == t_top) & (d[:, 2] < 0)
        return t, top

    def faces(self) -> list[Face]:
        r, h = self.radius, self.height

        def side(rng: np.random.Generator, n: int) -> np.ndarray:
            a = rng.random(n) * (2.0 * np.pi)
            z = (rng.random(n) - 0.5) * h
            return np.column_stack([r * np.cos(a), r * np.sin(a), z])

        disc = np.pi * r * r
        return [
            Face(2.0 * np.pi * r * h, False, side),
            Face(disc, True, disc_sampler(h / 2.0, r)),
            Face(disc, False, disc_sampler(-h / 2.0, r), bottom=True),
        ]


@dataclass(frozen=True)
class Sphere:
    """Sphere of `radius` metres, centred."""

    radius: float
    kind: str = "sphere"

    @property
    def bounding_radius(self) -> float:
        return float(self.radius)

    def contains(self, p: np.ndarray, eps: float) -> np.ndarray:
        """(N,) bool: shape-frame points (N, 3) inside the sphere grown by eps."""
        return np.einsum("ij,ij->i", p, p) <= (self.radius + eps) ** 2

    @property
    def half_extent(self) -> np.ndarray:
        """(3,) half sizes of the shape-frame box around the shape, metres."""
        return np.full(3, float(self.radius))

    def normals(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) outward unit normals at shape-frame surface points p (N, 3)."""
        return unit(p)

    @quiet
    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        b = np.einsum("ij,ij->i", o, d)
        c = np.einsum("ij,ij->i", o, o) - self.radius**2
        t1, t2 = quadratic_roots(np.ones_like(b), b, c)
        t = nearest_positive(t1, t2)
        return t, np.zeros(t.shape, bool)

    def faces(self) -> list[Face]:
        r = self.radius

        def sample(rng: np.random.Generator, n: int) -> np.ndarray:
            v = rng.standard_normal((n, 3))  # isotropic Gaussian, normalised: uniform on sphere
            return r * v / np.linalg.norm(v, axis=1, keepdims=True)

        return [Face(4.0 * np.pi * r * r, False, sample)]


@dataclass(frozen=True)
class Cone:
    """Cone along z: base disc of `radius` at z = -height/2, apex at z = +height/2, metres."""

    radius: float
    height: float
    kind: str = "cone"

    @property
    def bounding_radius(self) -> float:
        return float(np.hypot(self.radius, self.height / 2.0))

    def contains(self, p: np.ndarray, eps: float) -> np.ndarray:
        """(N,) bool: shape-frame points (N, 3) inside the cone grown by eps (apex at +h/2)."""
        h = self.height
        r_at = self.radius * np.clip((h / 2.0 - p[:, 2]) / h, 0.0, 1.0)
        r = np.sqrt(p[:, 0] ** 2 + p[:, 1] ** 2)
        return (r <= r_at + eps) & (np.abs(p[:, 2]) <= h / 2.0 + eps)

    @property
    def half_extent(self) -> np.ndarray:
        """(3,) half sizes of the shape-frame box around the shape, metres."""
        return np.array([self.radius, self.radius, self.height / 2.0])

    def normals(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) outward unit normals at shape-frame surface points p (N, 3)."""
        k = self.radius / self.height
        rho = np.hypot(p[:, 0], p[:, 1])
        # The lateral surface is f = rho - k (h/2 - z) = 0, whose gradient is (x/rho, y/rho, k).
        grad = np.column_stack([p[:, 0] / np.maximum(rho, 1e-12), p[:, 1] / np.maximum(rho, 1e-12)])
        side = unit(np.column_stack([grad, np.full(len(p), k)]))
        lateral = np.abs(rho - k * (self.height / 2.0 - p[:, 2])) / np.hypot(1.0, k)
        base = np.abs(p[:, 2] + self.height / 2.0)
        return pick([lateral, base], [side, np.broadcast_to([0.0, 0.0, -1.0], p.shape)])

    @quiet
    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h2 = self.height / 2.0
        k2 = (self.radius / self.height) ** 2
        # Lateral surface: x^2 + y^2 = k^2 w^2 with w = h/2 - z the depth below the apex.
        w0 = h2 - o[:, 2]
        a = d[:, 0] ** 2 + d[:, 1] ** 2 - k2 * d[:, 2] ** 2
        b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1] + k2 * w0 * d[:, 2]
        c = o[:, 0] ** 2 + o[:, 1] ** 2 - k2 * w0 * w0
        roots = quadratic_roots(a, b, c)
        # The quadric is a double cone; keep only the nappe below the apex.
        sides = [np.where(np.abs(o[:, 2] + s * d[:, 2]) <= h2, s, np.inf) for s in roots]
        t_base = disc_hit(o, d, -h2, self.radius)
        t = nearest_positive(sides[0], sides[1], t_base)
        return t, np.zeros(t.shape, bool)

    def faces(self) -> list[Face]:
        r, h = self.radius, self.height
        slant = float(np.hypot(r, h))

        def side(rng: np.random.Generator, n: int) -> np.ndarray:
            # Unrolled, the lateral surface is a circular sector: area density grows linearly
            # with the distance s from the apex, so s = L sqrt(u).
            f = np.sqrt(rng.random(n))
            a = rng.random(n) * (2.0 * np.pi)
            return np.column_stack([r * f * np.cos(a), r * f * np.sin(a), h / 2.0 - h * f])

        return [
            Face(np.pi * r * slant, False, side),
            Face(np.pi * r * r, False, disc_sampler(-h / 2.0, r), bottom=True),
        ]
