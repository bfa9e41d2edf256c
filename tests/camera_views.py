"""Depth-camera views of small scenes, scanned by the simulator, in the camera's optical frame.

Organised like a Kinect scan: (H * W, 3) float64 metres, x right, y down, z forward, NaN where a
pixel sees nothing, the simulator's Kinect noise. A 320 x 240 camera (58 deg wide) keeps each
view quick. Each function returns (points, the true up (3,) in the optical frame).
"""

from __future__ import annotations

import numpy as np

from supportnode.sim.cloud import OPTICAL_FROM_BODY
from supportnode.sim.depth_noise import kinect_noise
from supportnode.sim.scene import parse_scene
from supportnode.sim.sensors import DepthCamera
from supportnode.sim.trajectory import look_at

_CAMERA = DepthCamera(320, 240, 58.0, 0.2, 10.0)
TABLE = 0.75  # m, the table top


def _box(name: str, lo, hi, role: str = "object") -> str:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    size, xyz = (hi - lo).round(4).tolist(), ((lo + hi) / 2).round(4).tolist()
    tag = f", {role}: {name}" if role in ("object", "surface") else ""
    return f"{{kind: box, name: {name}, size: {size}, xyz: {xyz}, role: {role}{tag}}}"


def _can(name: str, x: float, y: float, radius: float, height: float) -> str:
    xyz = [round(float(x), 4), round(float(y), 4), TABLE + height / 2]
    return (
        f"{{kind: cylinder, name: {name}, radius: {radius}, height: {height}, xyz: {xyz}, "
        f"role: object, object: {name}}}"
    )


def scan(items: list[str], eye, direction, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The scene of ``items`` (YAML flow mappings) seen from ``eye`` (world, m) looking along
    ``direction``; (points, true up), both in the optical frame."""
    scene = parse_scene("primitives:\n" + "".join(f"  - {i}\n" for i in items), "camera_views")
    eye = np.asarray(eye, float)
    pose = look_at(eye, eye + np.asarray(direction, float))
    cloud = _CAMERA.scan(scene, pose, organized=True)
    cloud = kinect_noise(cloud, scene, _CAMERA, np.random.default_rng(seed))
    up = OPTICAL_FROM_BODY @ pose[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    return cloud.to_frame("optical").points.astype(np.float64), up


def tabletop(seed: int, pitch_down_deg: float = 45.0, yaw_deg: float = 0.0):
    """A table view like the mOSD scans: the table top only (no floor or wall in view) with a
    box standing on a box, a low box and two cans where the camera looks, 0.6 m above it."""
    height = 0.6
    p, y = np.radians([pitch_down_deg, yaw_deg])
    reach = height / np.tan(p)  # where the optical axis meets the table
    c, s = np.cos(y), np.sin(y)

    def at(ahead: float, left: float) -> np.ndarray:
        return np.array([(reach + ahead) * c - left * s, (reach + ahead) * s + left * c])

    def box(name, ahead, left, half, z0, z1):
        xy = at(ahead, left)
        return _box(name, [*(xy - half), TABLE + z0], [*(xy + half), TABLE + z1])

    items = [
        _box("table", [-3, -3, TABLE - 0.04], [3, 3, TABLE], role="surface"),
        box("low_box", 0.0, 0.0, 0.1, 0.0, 0.12),
        box("top_box", 0.0, 0.0, 0.07, 0.12, 0.2),  # standing on the box below
        box("flat_box", 0.0, 0.22, 0.06, 0.0, 0.08),
        _can("can", *at(0.05, -0.25), 0.035, 0.12),
        _can("jar", *at(0.25, 0.05), 0.04, 0.1),
    ]
    direction = [np.cos(p) * c, np.cos(p) * s, -np.sin(p)]
    return scan(items, [0.0, 0.0, TABLE + height], direction, seed)


def wall(seed: int):
    """A bare wall 1.5 m ahead of a level camera, nothing else."""
    items = [_box("wall", [1.5, -3, -1], [1.6, 3, 3], role="structure")]
    return scan(items, [0.0, 0.0, 1.2], [1.0, 0.0, 0.0], seed)


def room_with_shelf(seed: int):
    """A room seen by a camera 1.4 m up, pitched 5 deg down: floor, a table with a box on it,
    a far wall, and a shelf board at 1.8 m that the camera sees from below."""
    items = [
        _box("floor", [-1, -3, -0.02], [6, 3, 0], role="surface"),
        _box("table", [1.5, -0.5, 0.71], [2.5, 0.5, 0.75], role="surface"),
        _box("box", [1.8, -0.1, 0.75], [2.0, 0.1, 0.95]),
        _box("board", [2.0, -1.5, 1.8], [3.0, 1.5, 1.82], role="surface"),
        _box("wall", [6.0, -3, 0], [6.1, 3, 3], role="structure"),
    ]
    p = np.radians(5.0)
    return scan(items, [0.0, 0.0, 1.4], [np.cos(p), 0.0, -np.sin(p)], seed)
