"""What every primitive shares: faces for area sampling and the vectorised ray-hit helpers."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

EPS = 1e-9

# A face sampler draws n points uniformly by area: (rng, n) -> (n, 3) float64 in the shape frame.
Sampler = Callable[[np.random.Generator, int], np.ndarray]


@dataclass(frozen=True)
class Face:
    """One face of a shape: its area (m^2), whether it is the top (+z) or bottom (-z) face in
    the shape frame, and a sampler."""

    area: float
    top: bool
    sample: Sampler
    bottom: bool = False


def quiet(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Silence numpy warnings: misses and rays parallel to a face legitimately produce inf/NaN,
    which the intersection code turns into misses."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return fn(*args, **kwargs)

    return wrapper


def nearest_positive(*ts: np.ndarray) -> np.ndarray:
    """Per ray, the smallest candidate t > EPS (inf if none). Each ts[i] is (N,) float64."""
    stack = np.stack(ts)
    stack[~(stack > EPS)] = np.inf  # also turns NaN (degenerate rays) into misses
    return stack.min(axis=0)


@quiet
def disc_hit(
    o: np.ndarray, d: np.ndarray, z: float, radius: float, inner: float = 0.0
) -> np.ndarray:
    """t where rays cross the plane z inside a disc (or, with `inner` > 0, an annulus) about
    the z axis, radii in metres (else inf)."""
    t = (z - o[:, 2]) / d[:, 2]
    x = o[:, 0] + t * d[:, 0]
    y = o[:, 1] + t * d[:, 1]
    r2 = x * x + y * y
    return np.where((r2 <= radius * radius) & (r2 >= inner * inner), t, np.inf)


@quiet
def quadratic_roots(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both real roots of a t^2 + 2 b t + c = 0 (NaN where none). `a` near 0 gives the linear root."""
    sq = np.sqrt(b * b - a * c)
    linear = np.abs(a) < 1e-12
    t1 = np.where(linear, -c / (2.0 * b), (-b - sq) / a)
    t2 = np.where(linear, np.nan, (-b + sq) / a)
    return t1, t2


def side_hits(
    o: np.ndarray, d: np.ndarray, radius: float, z_lo: float, z_hi: float
) -> list[np.ndarray]:
    """Both t where rays meet the cylinder of `radius` about the z axis between z_lo and z_hi
    (inf where not)."""
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]
    c = o[:, 0] ** 2 + o[:, 1] ** 2 - radius * radius
    return [
        np.where((z >= z_lo) & (z <= z_hi), t, np.inf)
        for t in quadratic_roots(a, b, c)
        for z in [o[:, 2] + t * d[:, 2]]
    ]


def sphere_hits(
    o: np.ndarray, d: np.ndarray, radius: float, zc: float, z_lo: float, z_hi: float
) -> list[np.ndarray]:
    """Both t where unit rays meet the sphere of `radius` centred at (0, 0, zc) between the
    planes z_lo and z_hi (inf where not)."""
    oc = o - np.array([0.0, 0.0, zc])
    b = np.einsum("ij,ij->i", oc, d)
    c = np.einsum("ij,ij->i", oc, oc) - radius * radius
    return [
        np.where((z >= z_lo) & (z <= z_hi), t, np.inf)
        for t in quadratic_roots(np.ones_like(b), b, c)
        for z in [o[:, 2] + t * d[:, 2]]
    ]


def disc_sampler(z: float, radius: float, inner: float = 0.0) -> Sampler:
    """Uniform points on the disc (or annulus from `inner`) of `radius` in the plane z."""

    def sample(rng: np.random.Generator, n: int) -> np.ndarray:
        u = rng.random(n)  # sqrt below: uniform by area, not by radius
        if inner == 0.0:  # the disc's own formula: the same clouds per seed as before annuli
            r = radius * np.sqrt(u)
        else:
            r = np.sqrt(inner * inner + (radius * radius - inner * inner) * u)
        a = rng.random(n) * (2.0 * np.pi)
        return np.column_stack([r * np.cos(a), r * np.sin(a), np.full(n, z)])

    return sample


def side_sampler(radius: float, z_lo: float, z_hi: float) -> Sampler:
    """Uniform points on the cylinder of `radius` about z between z_lo and z_hi."""

    def sample(rng: np.random.Generator, n: int) -> np.ndarray:
        a = rng.random(n) * (2.0 * np.pi)
        z = z_lo + rng.random(n) * (z_hi - z_lo)
        return np.column_stack([radius * np.cos(a), radius * np.sin(a), z])

    return sample


def zone_sampler(radius: float, zc: float, z_lo: float, z_hi: float) -> Sampler:
    """Uniform points on the zone of the sphere (`radius`, centre (0, 0, zc)) between z_lo and
    z_hi: by Archimedes' hat-box theorem a zone's area is uniform in z."""

    def sample(rng: np.random.Generator, n: int) -> np.ndarray:
        z = z_lo + rng.random(n) * (z_hi - z_lo)
        r = np.sqrt(np.maximum(radius * radius - (z - zc) ** 2, 0.0))
        a = rng.random(n) * (2.0 * np.pi)
        return np.column_stack([r * np.cos(a), r * np.sin(a), z])

    return sample


def unit(v: np.ndarray) -> np.ndarray:
    """(N, 3) rows scaled to unit length (zero rows stay zero)."""
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return v / np.where(norm > 0, norm, 1.0)


def pick(dist: list[np.ndarray], normals: list[np.ndarray]) -> np.ndarray:
    """Per point, the normal of the face it lies nearest: dist[i] (N,) distances to face i,
    normals[i] (N, 3) that face's outward normal there."""
    best = np.argmin(np.stack(dist), axis=0)
    return np.stack(normals)[best, np.arange(best.size)]
