"""Sensor paths: poses (4x4 sensor-to-world, x forward, z up) looking at a point."""

from __future__ import annotations

from typing import Any

import numpy as np

from supportnode.sim.scene import Scene


def look_at(eye: Any, target: Any, level: bool = False) -> np.ndarray:
    """(4, 4) float64 pose at `eye` whose +x axis points at `target` (both (3,) metres) and
    whose +z axis is as close to world up as possible. `level` keeps x horizontal (yaw only),
    as for a lidar on a ground robot."""
    eye = np.asarray(eye, np.float64)
    fwd = np.asarray(target, np.float64) - eye
    if level:
        fwd[2] = 0.0
    norm = np.linalg.norm(fwd)
    fwd = np.array([1.0, 0.0, 0.0]) if norm < 1e-12 else fwd / norm
    left = np.cross([0.0, 0.0, 1.0], fwd)
    if np.linalg.norm(left) < 1e-9:  # looking straight up or down: any left will do
        left = np.array([0.0, 1.0, 0.0])
    left /= np.linalg.norm(left)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([fwd, left, np.cross(fwd, left)])
    pose[:3, 3] = eye
    return pose


def circle(
    center: Any,
    radius: float,
    n: int,
    target: Any = None,
    start_deg: float = 0.0,
    arc_deg: float = 360.0,
    level: bool = True,
) -> np.ndarray:
    """(n, 4, 4) poses on a horizontal circle about `center` ((3,) metres; its z is the sensor
    height), at angles start + arc * i / n, each looking at `target` (default: `center`)."""
    center = np.asarray(center, np.float64)
    target = center if target is None else np.asarray(target, np.float64)
    angles = np.radians(start_deg + arc_deg * np.arange(n) / max(n, 1))
    eyes = center + radius * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(n)])
    return np.stack([look_at(e, target, level) for e in eyes]) if n else np.zeros((0, 4, 4))


def line(start: Any, end: Any, n: int, target: Any = None, level: bool = True) -> np.ndarray:
    """(n, 4, 4) poses evenly from `start` to `end` (inclusive, metres), looking at `target`
    (default: along the line)."""
    start, end = np.asarray(start, np.float64), np.asarray(end, np.float64)
    eyes = start + np.linspace(0.0, 1.0, n)[:, None] * (end - start) if n > 1 else start[None]
    if target is None:
        return np.stack([look_at(e, e + (end - start), level) for e in eyes[:n]])
    return np.stack([look_at(e, target, level) for e in eyes[:n]])


def default_trajectory(scene: Scene) -> dict[str, Any]:
    """The scene's `trajectory:` entry, or a circle at 1.2 m height inside its bounding box."""
    if scene.trajectory:
        return dict(scene.trajectory)
    lo, hi = scene.bounds()
    mid = (lo + hi) / 2.0
    radius = 0.35 * float(min(hi[0] - lo[0], hi[1] - lo[1]))
    return {"kind": "circle", "center": [mid[0], mid[1], lo[2] + 1.2], "radius": radius}


def poses_for(scene: Scene, n: int, level: bool = True) -> np.ndarray:
    """(n, 4, 4) poses along the scene's trajectory; `level` unless the scene file says."""
    spec = default_trajectory(scene)
    level = bool(spec.get("level", level))
    if spec["kind"] == "circle":
        return circle(
            spec["center"],
            spec["radius"],
            n,
            spec.get("target"),
            spec.get("start_deg", 0.0),
            spec.get("arc_deg", 360.0),
            level,
        )
    return line(spec["start"], spec["end"], n, spec.get("target"), level)
