"""Depth-camera views of small synthetic scenes, ray cast in the camera's optical frame.

Organised like a Kinect scan: (H * W, 3) float64 metres, x right, y down, z forward, NaN where a
pixel's ray hits nothing, axial noise growing with the square of the range. Used by the gravity
and CLI tests; built in the test, never read from outside the repository.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

OPTICAL_FROM_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class Scene:
    """World frame, z up. rects: horizontal rectangles (x0, x1, y0, y1, z); boxes: (lo, hi)
    corners; cylinders: upright (cx, cy, radius, z0, z1); walls: planes x = const spanning
    (x, y0, y1, z0, z1)."""

    rects: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]] = field(
        default_factory=list
    )
    cylinders: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    walls: list[tuple[float, float, float, float, float]] = field(default_factory=list)


def _hit_rects(o, d, rects):
    t = np.full(d.shape[0], np.inf)
    for x0, x1, y0, y1, z in rects:
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - o[2]) / d[:, 2]
        p = o + s[:, None] * d
        ok = (s > 0) & (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
        t = np.where(ok & (s < t), s, t)
    return t


def _hit_boxes(o, d, boxes):
    t = np.full(d.shape[0], np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
    for lo, hi in boxes:
        a = (np.asarray(lo) - o) * inv
        b = (np.asarray(hi) - o) * inv
        near = np.nanmax(np.minimum(a, b), axis=1)
        far = np.nanmin(np.maximum(a, b), axis=1)
        ok = (near <= far) & (near > 0)
        t = np.where(ok & (near < t), near, t)
    return t


def _hit_cylinders(o, d, cylinders):
    t = np.full(d.shape[0], np.inf)
    for cx, cy, r, z0, z1 in cylinders:
        ox, oy = o[0] - cx, o[1] - cy
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = 2 * (ox * d[:, 0] + oy * d[:, 1])
        c = ox**2 + oy**2 - r**2
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            s = (-b - np.sqrt(disc)) / (2 * a)
        z = o[2] + s * d[:, 2]
        ok = (disc >= 0) & (s > 0) & (z >= z0) & (z <= z1)
        t = np.where(ok & (s < t), s, t)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z1 - o[2]) / d[:, 2]  # the top cap
        p = o + s[:, None] * d
        ok = (s > 0) & ((p[:, 0] - cx) ** 2 + (p[:, 1] - cy) ** 2 <= r * r)
        t = np.where(ok & (s < t), s, t)
    return t


def _hit_walls(o, d, walls):
    t = np.full(d.shape[0], np.inf)
    for x, y0, y1, z0, z1 in walls:
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (x - o[0]) / d[:, 0]
        p = o + s[:, None] * d
        ok = (s > 0) & (p[:, 1] >= y0) & (p[:, 1] <= y1) & (p[:, 2] >= z0) & (p[:, 2] <= z1)
        t = np.where(ok & (s < t), s, t)
    return t


def camera_rotation(pitch_down_deg: float, yaw_deg: float = 0.0, roll_deg: float = 0.0):
    """(3, 3) optical-from-world rotation of a camera looking along world +x turned by yaw,
    pitched down by ``pitch_down_deg`` and rolled about its optical axis."""
    p, y, r = np.radians([pitch_down_deg, yaw_deg, roll_deg])
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    body_from_world = (rz @ ry).T
    rc = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])
    return rc @ OPTICAL_FROM_BODY @ body_from_world


def render(
    scene: Scene,
    position,
    optical_from_world: np.ndarray,
    rng: np.random.Generator,
    size: tuple[int, int] = (320, 240),
    hfov_deg: float = 58.0,
) -> np.ndarray:
    """Depth image of ``scene`` from a camera at ``position`` (world, m): (H * W, 3) float64 in
    the optical frame, row-major, NaN where nothing is hit. Axial noise sigma 1.5 mm * z^2."""
    w, h = size
    f = (w / 2) / np.tan(np.radians(hfov_deg) / 2)
    v, u = np.meshgrid(np.arange(h) + 0.5 - h / 2, np.arange(w) + 0.5 - w / 2, indexing="ij")
    rays = np.stack([u / f, v / f, np.ones_like(u)], axis=-1).reshape(-1, 3)  # z = 1
    d = rays @ optical_from_world  # world directions (rows: R^T r)
    o = np.asarray(position, dtype=np.float64)
    t = np.minimum.reduce(
        [
            _hit_rects(o, d, scene.rects),
            _hit_boxes(o, d, scene.boxes),
            _hit_cylinders(o, d, scene.cylinders),
            _hit_walls(o, d, scene.walls),
        ]
    )
    hit = np.isfinite(t)
    t = np.where(hit, t + rng.normal(0.0, 0.0015, t.shape) * np.where(hit, t, 0.0) ** 2, np.nan)
    return rays * t[:, None]  # depth = t on a z = 1 ray


def tabletop(rng: np.random.Generator, pitch_down_deg: float = 45.0, yaw_deg: float = 0.0):
    """A table view like the mOSD scans: the table top only (no floor or wall) with a box
    standing on a box, a low box and two cans around the point the camera looks at, from 0.6 m
    above the table. Returns (points (N, 3) optical frame with NaN rows, true up (3,) in the
    optical frame)."""
    table, height = 0.75, 0.6
    reach = height / np.tan(np.radians(pitch_down_deg))  # optical axis meets the table there
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))

    def at(ahead: float, left: float) -> tuple[float, float]:
        """World x, y of a point `ahead` of the camera's foot along its view, `left` of it."""
        return (reach + ahead) * c - left * s, (reach + ahead) * s + left * c

    def box(ahead, left, half, z0, z1):
        x, y = at(ahead, left)
        return (x - half, y - half, table + z0), (x + half, y + half, table + z1)

    scene = Scene(
        rects=[(-2.0, 2.0, -2.0, 2.0, table)],
        boxes=[
            box(0.0, 0.0, 0.1, 0.0, 0.12),
            box(0.0, 0.0, 0.07, 0.12, 0.2),  # standing on the box below
            box(0.0, 0.22, 0.06, 0.0, 0.08),
        ],
        cylinders=[
            (*at(0.05, -0.25), 0.035, table, table + 0.12),
            (*at(0.25, 0.05), 0.04, table, table + 0.1),
        ],
    )
    rot = camera_rotation(pitch_down_deg, yaw_deg)
    pts = render(scene, (0.0, 0.0, table + height), rot, rng)
    return pts, rot @ np.array([0.0, 0.0, 1.0])


def wall(rng: np.random.Generator):
    """A bare wall 1.5 m ahead of a level camera, nothing else: (points, true up)."""
    scene = Scene(walls=[(1.5, -2.0, 2.0, 0.0, 2.5)])
    rot = camera_rotation(0.0)
    return render(scene, (0.0, 0.0, 1.2), rot, rng), rot @ np.array([0.0, 0.0, 1.0])


def room_with_shelf(rng: np.random.Generator):
    """A room seen by a camera 1.4 m up, pitched 5 deg down: floor, a table with a box on it,
    and a shelf board at 1.8 m that the camera sees from below. Returns (points in the
    optical frame, true up in the optical frame)."""
    scene = Scene(
        rects=[
            (-1.0, 6.0, -3.0, 3.0, 0.0),
            (1.5, 2.5, -0.5, 0.5, 0.75),
            (2.0, 3.0, -1.5, 1.5, 1.8),
        ],
        boxes=[((1.8, -0.1, 0.75), (2.0, 0.1, 0.95))],
        walls=[(6.0, -3.0, 3.0, 0.0, 3.0)],
    )
    rot = camera_rotation(5.0)
    return render(scene, (0.0, 0.0, 1.4), rot, rng), rot @ np.array([0.0, 0.0, 1.0])
