"""Seeded noise for simulated clouds, parsed from short specs such as ``uniform:0.05``.

Specs (repeatable, later ones override earlier ones of the same kind):
- ``uniform:A``   the report's noise: every coordinate moves by U[0, A] metres (one-sided, as in
  the report, so the cloud shifts by A/2 on average).
- ``gauss:S``     isotropic Gaussian, sigma S metres per axis.
- ``range:S``     Gaussian of sigma S metres along the ray from the sensor (scans).
- ``outliers:F``  add round(F * N) points uniformly in the scene's bounding box, role OUTLIER.
- ``tilt:R,P``    rotate the whole cloud about its frame's origin by roll R and pitch P degrees
  (a missing or wrong IMU); the rotation is kept in `SimCloud.tilt_rotation`.
- ``kinect`` or ``kinect:S``  a structured-light depth camera's noise, holes and depth steps
  (`supportnode.sim.depth_noise`), sigmas times S (default 1); depth cameras only.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

from supportnode.errors import ConfigError
from supportnode.sim.cloud import ROLE_OUTLIER, SimCloud, concatenate, rotate
from supportnode.sim.scene import rpy_matrix

_KINDS = ("uniform", "gauss", "range", "outliers", "tilt", "kinect")


@dataclass(frozen=True)
class NoiseSpec:
    """Noise amounts: metres for uniform/gauss/range, a fraction for outliers, degrees for tilt,
    a scale of the depth-camera model for kinect (0: off)."""

    uniform: float = 0.0
    gauss: float = 0.0
    range: float = 0.0
    outliers: float = 0.0
    tilt: tuple[float, float] = (0.0, 0.0)
    kinect: float = 0.0

    @property
    def is_zero(self) -> bool:
        return self == NoiseSpec()


def parse_noise(specs: Iterable[str]) -> NoiseSpec:
    """A NoiseSpec from strings like ``["uniform:0.05", "tilt:2,-1"]``; ConfigError if invalid."""
    spec = NoiseSpec()
    for text in specs:
        kind, sep, value = text.partition(":")
        if text == "kinect":
            kind, sep, value = "kinect", ":", "1"
        if not sep or kind not in _KINDS:
            raise ConfigError(
                f"noise {text!r}: expected KIND:VALUE with KIND one of {', '.join(_KINDS)}"
            )
        try:
            numbers = [float(v) for v in value.split(",")]
        except ValueError:
            raise ConfigError(f"noise {text!r}: {value!r} is not a number") from None
        if not all(math.isfinite(v) for v in numbers):
            raise ConfigError(f"noise {text!r}: values must be finite")
        if kind == "tilt":
            if len(numbers) != 2 or any(abs(v) > 90 for v in numbers):
                raise ConfigError(
                    f"noise {text!r}: expected tilt:ROLL,PITCH in degrees (|x| <= 90)"
                )
            spec = replace(spec, tilt=(numbers[0], numbers[1]))
            continue
        if len(numbers) != 1 or numbers[0] < 0:
            raise ConfigError(f"noise {text!r}: expected one non-negative number")
        if kind == "outliers" and numbers[0] > 1:
            raise ConfigError(f"noise {text!r}: the outlier fraction must be in [0, 1]")
        spec = replace(spec, **{kind: numbers[0]})  # type: ignore[arg-type]  # kind is a float field
    return spec


def apply_noise(
    cloud: SimCloud, spec: NoiseSpec, bounds: np.ndarray, rng: np.random.Generator
) -> SimCloud:
    """Point noise and outliers (not tilt, see `apply_tilt`) on a world-frame cloud.

    bounds: (2, 3) [min, max] box for outliers, metres. Range noise follows the ray from the
    sensor origin `cloud.sensor_pose[:3, 3]`. Labels are unchanged; outliers are appended.
    """
    if cloud.frame != "world":
        raise ValueError("apply_noise expects a world-frame cloud")
    pts = cloud.points.astype(np.float64)
    n = len(pts)
    if spec.range > 0 and n:
        ray = pts - cloud.sensor_pose[:3, 3]
        dist = np.linalg.norm(ray, axis=1, keepdims=True)
        pts += ray / np.maximum(dist, 1e-12) * rng.normal(0.0, spec.range, (n, 1))
    if spec.gauss > 0:
        pts += rng.normal(0.0, spec.gauss, pts.shape)
    if spec.uniform > 0:
        pts += rng.uniform(0.0, spec.uniform, pts.shape)
    out = replace(cloud, points=pts.astype(np.float32))
    n_out = round(spec.outliers * n)
    if n_out:
        lo, hi = np.asarray(bounds, np.float64)
        noise = SimCloud(
            points=rng.uniform(lo, hi, (n_out, 3)).astype(np.float32),
            role=np.full(n_out, ROLE_OUTLIER, np.int8),
            primitive=np.full(n_out, -1, np.int32),
            object=np.full(n_out, -1, np.int32),
            surface=np.full(n_out, -1, np.int32),
            supported_by=np.full(n_out, -1, np.int32),
            support_surface=np.full(n_out, -1, np.int32),
        )
        out = concatenate([out, noise])
    return out


def apply_tilt(cloud: SimCloud, roll_deg: float, pitch_deg: float) -> SimCloud:
    """Rotate the points about the origin of their frame: points' = R @ points with
    R = Ry(pitch) Rx(roll). `tilt_rotation` accumulates R; `sensor_pose` stays the true pose."""
    rot = rpy_matrix((roll_deg, pitch_deg, 0.0))
    pts = rotate(cloud.points.astype(np.float64), rot).astype(np.float32)
    return replace(cloud, points=pts, tilt_rotation=rot @ cloud.tilt_rotation)
