"""The rules planners rely on, in one place: when a detected surface is ``safe``."""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from supportnode.params import SafeParams

__all__ = ["is_safe"]


class _SurfaceLike(Protocol):
    area: float
    flatness: float
    normal: np.ndarray


def is_safe(surface: _SurfaceLike, params: SafeParams, hits: int = 1, min_hits: int = 1) -> bool:
    """Whether a planner may put something down on ``surface``: footprint ``area`` (m^2) at
    least ``params.min_area``, ``flatness`` (rms distance to its plane, m) at most
    ``params.max_flatness``, unit ``normal`` (3,) within ``params.max_tilt_deg`` of +z, and
    seen in ``hits`` >= ``min_hits`` detections in a row (the node's tracking)."""
    tilt = math.degrees(math.acos(min(1.0, abs(float(surface.normal[2])))))
    return (
        surface.area >= params.min_area
        and surface.flatness <= params.max_flatness
        and tilt <= params.max_tilt_deg
        and hits >= min_hits
    )
