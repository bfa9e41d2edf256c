"""A torus, whole or as an arc with flat ends (a mug's handle), about the z axis of its frame
(frames and ray conventions: see the package)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from supportnode.sim.primitives.base import Face, nearest_positive, pick, quiet, unit

_IMAG = 1e-6  # roots whose imaginary part (m) exceeds this are no hits
_NEWTON = 3  # Newton steps that polish each real root of the quartic


@dataclass(frozen=True)
class Torus:
    """A tube of `minor_radius` swept around a circle of `major_radius` in the xy plane,
    metres. `arc_deg` < 360 keeps the arc centred on +x from -arc/2 to +arc/2, closed by flat
    round ends."""

    major_radius: float
    minor_radius: float
    arc_deg: float = 360.0
    kind: str = "torus"

    def __post_init__(self) -> None:
        if not 0 < self.minor_radius < self.major_radius:
            raise ValueError("minor_radius must be positive and less than major_radius")
        if not 0 < self.arc_deg <= 360:
            raise ValueError("arc_deg must be in (0, 360]")

    @property
    def whole(self) -> bool:
        return self.arc_deg >= 360.0

    @property
    def bounding_radius(self) -> float:
        return float(self.major_radius + self.minor_radius)

    @property
    def half_extent(self) -> np.ndarray:
        """(3,) half sizes of the shape-frame box around the shape, metres."""
        r = self.bounding_radius
        return np.array([r, r, self.minor_radius])

    def _in_arc(self, p: np.ndarray, slack: float = 0.0) -> np.ndarray:
        if self.whole:
            return np.ones(len(p), bool)
        half = math.radians(self.arc_deg) / 2.0 + slack / self.major_radius
        return np.abs(np.arctan2(p[:, 1], p[:, 0])) <= half

    def _tube_distance(self, p: np.ndarray) -> np.ndarray:
        """(N,) distance of each point from the circle at the tube's centre, metres."""
        return np.hypot(np.hypot(p[:, 0], p[:, 1]) - self.major_radius, p[:, 2])

    def _ends(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Centre and outward normal of each flat end ([] for a whole torus)."""
        if self.whole:
            return []
        half = math.radians(self.arc_deg) / 2.0
        out = []
        for sign in (1.0, -1.0):
            a = sign * half
            centre = self.major_radius * np.array([math.cos(a), math.sin(a), 0.0])
            out.append((centre, sign * np.array([-math.sin(a), math.cos(a), 0.0])))
        return out

    def contains(self, p: np.ndarray, eps: float) -> np.ndarray:
        """(N,) bool: shape-frame points (N, 3) inside the tube grown by eps."""
        return (self._tube_distance(p) <= self.minor_radius + eps) & self._in_arc(p, eps)

    @quiet
    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t_tube = self._tube_hits(o, d)
        t_ends = [
            np.where(np.linalg.norm(o + t[:, None] * d - c, axis=1) <= self.minor_radius, t, np.inf)
            for c, n in self._ends()
            for t in [((c - o) @ n) / (d @ n)]
        ]
        t = nearest_positive(*t_tube, *t_ends)
        return t, np.zeros(t.shape, bool)

    def _tube_hits(self, o: np.ndarray, d: np.ndarray) -> list[np.ndarray]:
        """The four roots of the ray-torus quartic (inf where complex or outside the arc).

        With the ray restarted at its point nearest the centre (s), |o|^2 + t^2 + 2 t o.d - the
        torus is (|p|^2 + R^2 - r^2)^2 = 4 R^2 (x^2 + y^2): a quartic in t, solved for all rays
        at once through the eigenvalues of its companion matrices, then polished by Newton.
        """
        n = len(o)
        if n == 0:
            return [np.zeros(0)] * 4
        big, small = self.major_radius, self.minor_radius
        s = -np.einsum("ij,ij->i", o, d)
        o2 = o + s[:, None] * d  # nearest the centre: keeps the coefficients well scaled
        b = np.einsum("ij,ij->i", o2, d)
        q = np.einsum("ij,ij->i", o2, o2) + big * big - small * small
        dxy = d[:, 0] ** 2 + d[:, 1] ** 2
        oxy = o2[:, 0] * d[:, 0] + o2[:, 1] * d[:, 1]
        c3 = 4.0 * b
        c2 = 4.0 * b * b + 2.0 * q - 4.0 * big * big * dxy
        c1 = 4.0 * b * q - 8.0 * big * big * oxy
        c0 = q * q - 4.0 * big * big * (o2[:, 0] ** 2 + o2[:, 1] ** 2)
        comp = np.zeros((n, 4, 4))
        comp[:, 0, :] = -np.column_stack([c3, c2, c1, c0])
        comp[:, 1, 0] = comp[:, 2, 1] = comp[:, 3, 2] = 1.0
        roots = np.linalg.eigvals(comp)  # (n, 4) complex
        real = np.abs(roots.imag) <= _IMAG
        t = roots.real
        for _ in range(_NEWTON):
            f = (((t + c3[:, None]) * t + c2[:, None]) * t + c1[:, None]) * t + c0[:, None]
            df = ((4.0 * t + 3.0 * c3[:, None]) * t + 2.0 * c2[:, None]) * t + c1[:, None]
            t = t - np.where(np.abs(df) > 1e-18, f / df, 0.0)
        t = t + s[:, None]  # back to the ray's own origin
        out = []
        for k in range(4):
            p = o + t[:, k, None] * d
            ok = real[:, k] & self._in_arc(p)
            ok &= np.abs(self._tube_distance(p) - small) <= 1e-6 + 1e-6 * small
            out.append(np.where(ok, t[:, k], np.inf))
        return out

    def faces(self) -> list[Face]:
        big, small = self.major_radius, self.minor_radius
        arc = math.radians(self.arc_deg)

        def tube(rng: np.random.Generator, n: int) -> np.ndarray:
            # Area element (R + r cos v) du dv: keep v with probability (R + r cos v) / (R + r).
            got: list[np.ndarray] = []
            have = 0
            while have < n:
                v = rng.random(2 * (n - have) + 8) * (2.0 * np.pi)
                v = v[rng.random(v.size) * (big + small) <= big + small * np.cos(v)]
                got.append(v)
                have += v.size
            v = np.concatenate(got)[:n]
            u = (rng.random(n) - 0.5) * arc
            ring = big + small * np.cos(v)
            return np.column_stack([ring * np.cos(u), ring * np.sin(u), small * np.sin(v)])

        faces = [Face(arc * small * 2.0 * np.pi * big, False, tube)]
        for centre, normal in self._ends():
            faces.append(Face(np.pi * small * small, False, _end_sampler(centre, normal, small)))
        return faces

    def normals(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) outward unit normals at shape-frame surface points p (N, 3)."""
        rho = np.maximum(np.hypot(p[:, 0], p[:, 1]), 1e-12)
        ring = p * [1.0, 1.0, 0.0] * (self.major_radius / rho)[:, None]
        tube = unit(p - ring)
        gaps = [np.abs(self._tube_distance(p) - self.minor_radius)]
        normals = [tube]
        for centre, normal in self._ends():
            gaps.append(np.abs((p - centre) @ normal))
            normals.append(np.broadcast_to(normal, p.shape))
        return pick(gaps, normals)


def _end_sampler(centre: np.ndarray, normal: np.ndarray, radius: float):
    """Uniform points on the disc of `radius` about `centre` facing `normal` (horizontal)."""
    side = np.cross([0.0, 0.0, 1.0], normal)

    def sample(rng: np.random.Generator, n: int) -> np.ndarray:
        r = radius * np.sqrt(rng.random(n))
        a = rng.random(n) * (2.0 * np.pi)
        return centre + np.outer(r * np.cos(a), side) + np.outer(r * np.sin(a), [0.0, 0.0, 1.0])

    return sample
