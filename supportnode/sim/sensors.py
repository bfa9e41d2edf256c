"""Sensors: area sampling of the scene mesh, ray casting, a spinning lidar and a depth camera.

Sensor frames follow REP-103 (x forward, y left, z up), for the camera too, so one pose convention
serves both; `OPTICAL_FROM_BODY` converts camera points to the optical convention (z forward,
x right, y down) if needed.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from supportnode.sim.cloud import (
    OPTICAL_FROM_BODY,
    ROLE_SURFACE,
    SimCloud,
    empty_cloud,
    rotate,
)
from supportnode.sim.scene import Scene

__all__ = [
    "OPTICAL_FROM_BODY",
    "DepthCamera",
    "Lidar",
    "raycast",
    "sample_scene",
    "surface_normals",
]

_CHUNK = 1 << 20  # points generated per face per step when sampling: bounds temporary memory


def _labels(scene: Scene, prim: np.ndarray, top: np.ndarray) -> tuple[np.ndarray, ...]:
    """role (int8), object, surface, supported_by, support_surface (int32) for hits on
    primitives `prim` ((N,) int)."""
    table = scene.label_table()
    role = np.where(top, table["role_top"][prim], table["role_other"][prim]).astype(np.int8)
    surface = np.where(role == ROLE_SURFACE, table["surface_top"][prim], -1).astype(np.int32)
    return (
        role,
        table["object"][prim],
        surface,
        table["supported_by"][prim],
        table["support_surface"][prim],
    )


def sample_scene(
    scene: Scene, n_points: int, seed: int = 0, include_bottoms: bool = False
) -> SimCloud:
    """Exactly `n_points` points spread uniformly by area over the faces of every primitive (a
    mesh sampling, as in the report), world frame, float32 metres.

    Faces turned to the ground (the bottom of an object, the underside of the floor slab or a
    seat) are left out unless `include_bottoms`: no sensor above them sees them, and an object's
    bottom coincides with the surface it stands on, so no method could tell the two apart.
    Likewise points inside (or within 1 mm of) another primitive are left out and drawn again:
    a cabinet top under a worktop, a leg's end inside a table top.

    Points come grouped by primitive and face, in scene order. Memory: the output plus one
    chunk (about 1M points) of temporaries, so tens of millions of points are fine.
    """
    if n_points < 0:
        raise ValueError("n_points must be >= 0")
    rng = np.random.default_rng(seed)
    faces = [
        (p, f)
        for p in scene.primitives
        for f in p.shape.faces()
        # A bottom face points down in the world when the primitive is not turned over.
        if include_bottoms or not (f.bottom and p.pose[2, 2] > 0.5)
    ]
    visible, blockers = _visible_shares(scene, faces, seed)
    areas = np.array([f.area for _, f in faces]) * np.array(visible)
    counts = rng.multinomial(n_points, areas / areas.sum()) if areas.sum() > 0 else 0 * areas
    table = scene.label_table()
    out = empty_cloud(n_points)
    start = 0
    for (prim, face), count, share, others in zip(faces, counts, visible, blockers, strict=True):
        _draw_face(out, slice(start, start + count), prim, face, share, others, rng, table)
        start += count
    return out


def _visible_shares(scene: Scene, faces: list, seed: int) -> tuple[list[float], list[list]]:
    """Visible share of each (primitive, face) and the primitives that may hide part of it.

    From a pilot sample (its own seeded stream), so that hidden area does not take points away
    from visible area. Only primitives whose box meets the face's box can hide part of it."""
    pilot = np.random.default_rng([seed, 1])
    boxes = np.array([p.world_aabb() for p in scene.primitives])  # (P, 2, 3)
    visible, blockers = [], []
    for prim, face in faces:  # one vectorised test per face (tens to hundreds of faces)
        probe = _face_points(prim, face, pilot, 4000)
        # The samples stop short of the face's edges by about extent / sqrt(4000): widen.
        lo, hi = probe.min(axis=0), probe.max(axis=0)
        pad = 0.05 * (hi - lo) + 2e-3
        lo, hi = lo - pad, hi + pad
        meets = np.all((boxes[:, 0] <= hi) & (boxes[:, 1] >= lo), axis=1)
        meets[prim.index] = False
        others = [scene.primitives[i] for i in np.flatnonzero(meets)]
        blockers.append(others)
        visible.append(_visible(others, probe).mean())
    return visible, blockers


def _draw_face(
    out: SimCloud,
    sl: slice,
    prim,
    face,
    share: float,
    others: list,
    rng: np.random.Generator,
    table: dict[str, np.ndarray],
) -> None:
    """Fill the rows ``sl`` of ``out`` with points drawn on one face, none hidden by
    ``others``, and their labels; ``share``: the face's visible share."""
    i = prim.index
    is_surface = face.top and prim.role == "surface"
    out.role[sl] = table["role_top"][i] if face.top else table["role_other"][i]
    out.primitive[sl] = i
    out.object[sl] = prim.object_id
    out.surface[sl] = prim.surface_id if is_surface else -1
    out.supported_by[sl] = table["supported_by"][i]
    out.support_surface[sl] = table["support_surface"][i]
    start, count = sl.start, sl.stop - sl.start
    filled = 0
    while filled < count:  # draw, drop hidden points, draw again for what is missing
        want = min(_CHUNK, count - filled)
        pts = _face_points(prim, face, rng, int(want / max(share, 1e-3) * 1.1) + 16)
        pts = pts[_visible(others, pts)][:want]
        out.points[start + filled : start + filled + len(pts)] = pts
        filled += len(pts)


def _face_points(prim, face, rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) world points drawn uniformly on one face of a primitive."""
    return rotate(face.sample(rng, n), prim.pose[:3, :3]) + prim.pose[:3, 3]


def _visible(others: list, pts: np.ndarray, eps: float = 1e-3) -> np.ndarray:
    """(N,) bool: world points not inside (nor within eps of) any of the primitives `others`."""
    ok = np.ones(len(pts), dtype=bool)
    for other in others:  # the few primitives that can reach the face
        box = other.world_aabb()
        near = np.flatnonzero(ok & np.all((pts >= box[0] - eps) & (pts <= box[1] + eps), axis=1))
        if len(near) == 0:
            continue
        local = rotate(pts[near] - other.pose[:3, 3], other.pose[:3, :3].T)
        ok[near[other.shape.contains(local, eps)]] = False
    return ok


def raycast(
    scene: Scene, origin: np.ndarray, dirs: np.ndarray, max_range: float = np.inf
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest hit of each ray in the scene (occlusion: the closest primitive wins).

    origin: (3,) float64 world position shared by all rays, metres. dirs: (N, 3) float64 unit
    world directions. Returns t (N,) float64 range (inf for no hit within max_range), prim (N,)
    int32 primitive index (-1 for none), top (N,) bool (hit on the primitive's +z face).

    One vectorised test per primitive over the rays that pass its bounding sphere and could still
    beat the current nearest hit; primitives are visited nearest first so far ones are culled.
    """
    origin = np.asarray(origin, np.float64)
    n = dirs.shape[0]
    best = np.full(n, float(max_range))
    prim = np.full(n, -1, np.int32)
    top = np.zeros(n, bool)
    centres = np.array([p.pose[:3, 3] for p in scene.primitives]) - origin
    order = np.argsort(np.linalg.norm(centres, axis=1))
    for k in order:
        p = scene.primitives[k]
        c, r = centres[k], p.shape.bounding_radius
        tc = dirs @ c  # distance along each ray to the point nearest the sphere centre
        miss2 = c @ c - tc * tc
        cand = np.flatnonzero((miss2 <= r * r) & (tc + r > 0) & (tc - r < best))
        if cand.size == 0:
            continue
        rot = p.pose[:3, :3]
        o_local = np.broadcast_to(-c @ rot, (cand.size, 3))  # origin in the shape frame
        d_local = rotate(dirs[cand], rot.T)
        t, t_top = p.shape.intersect(o_local, d_local)
        closer = t < best[cand]
        idx = cand[closer]
        best[idx] = t[closer]
        prim[idx] = k
        top[idx] = t_top[closer]
    best[prim < 0] = np.inf
    return best, prim, top


def surface_normals(scene: Scene, primitive: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) float64 outward unit world normals at world surface `points` (N, 3) of the
    primitives `primitive` (N,) int; NaN rows where primitive < 0."""
    out = np.full((len(points), 3), np.nan)
    for k in np.unique(primitive[primitive >= 0]):
        idx = np.flatnonzero(primitive == k)
        p = scene.primitives[k]
        rot = p.pose[:3, :3]
        local = rotate(points[idx].astype(np.float64) - p.pose[:3, 3], rot.T)
        out[idx] = rotate(p.shape.normals(local), rot)
    return out


def _scan(
    scene: Scene,
    dirs_sensor: np.ndarray,
    pose: np.ndarray,
    min_range: float,
    max_range: float,
    stamp: float,
    projector: np.ndarray | None = None,
    image_shape: tuple[int, int] | None = None,
) -> SimCloud:
    """Cast sensor-frame unit rays from `pose` (4x4 sensor-to-world); world-frame SimCloud.

    projector: (3,) sensor-frame position of a structured-light projector: hits it cannot see
    are lost (the shadow beside a near object). image_shape: keep a NaN row for every ray
    that returns nothing (an organised cloud) instead of dropping it."""
    pose = np.asarray(pose, np.float64)
    dirs = rotate(dirs_sensor, pose[:3, :3])
    t, prim, top = raycast(scene, pose[:3, 3], dirs, max_range)
    # A return closer than min_range is blocked by the near object, not seen through it.
    ok = (prim >= 0) & (t >= min_range)
    points = pose[:3, 3] + dirs * np.where(ok, t, np.nan)[:, None]
    if projector is not None:
        ok &= ~_shadowed(scene, pose[:3, :3] @ projector + pose[:3, 3], points, ok)
    keep = np.arange(len(t)) if image_shape is not None else np.flatnonzero(ok)
    role, obj, surface, by, under = _labels(scene, np.where(ok, prim, 0)[keep], top[keep])
    cloud = SimCloud(
        points=points[keep].astype(np.float32),
        role=role,
        primitive=prim[keep],
        object=obj,
        surface=surface,
        supported_by=by,
        support_surface=under,
        sensor_pose=pose.copy(),
        stamp=float(stamp),
        image_shape=image_shape,
    )
    return cloud if image_shape is None else cloud.without_returns(~ok)


def _shadowed(scene: Scene, source: np.ndarray, points: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(N,) bool: points (where `ok`) that something hides from the world position `source`."""
    out = np.zeros(len(points), bool)
    idx = np.flatnonzero(ok)
    ray = points[idx] - source
    dist = np.sqrt(np.einsum("ij,ij->i", ray, ray))
    t, _, _ = raycast(scene, source, ray / dist[:, None], float(dist.max(initial=0.0)))
    out[idx] = t < dist - 1e-3  # 1 mm: the point's own surface is no blocker
    return out


@dataclass(frozen=True)
class Lidar:
    """Spinning multi-beam lidar: `beams` rings evenly spread over [fov_min_deg, fov_max_deg]
    elevation, `columns` azimuth steps over 360 degrees, ranges in metres, rate in Hz."""

    beams: int = 16
    fov_min_deg: float = -15.0
    fov_max_deg: float = 15.0
    columns: int = 1800
    min_range: float = 0.3
    max_range: float = 100.0
    rate: float = 10.0

    @classmethod
    def preset(cls, name: str) -> Lidar:
        """`vlp16` (16 beams, -15..15 deg, 1800 columns) or `os128` (128, -22.5..22.5, 1024)."""
        presets = {
            "vlp16": cls(16, -15.0, 15.0, 1800, 0.3, 100.0, 10.0),
            "os128": cls(128, -22.5, 22.5, 1024, 0.3, 120.0, 10.0),
        }
        if name not in presets:
            raise ValueError(f"unknown lidar preset {name!r} (expected {', '.join(presets)})")
        return presets[name]

    def directions(self) -> np.ndarray:
        """(beams * columns, 3) float64 unit rays in the sensor frame, ring-major."""
        el = np.radians(np.linspace(self.fov_min_deg, self.fov_max_deg, self.beams))
        az = np.arange(self.columns) * (2.0 * np.pi / self.columns)
        el, az = np.meshgrid(el, az, indexing="ij")
        ce = np.cos(el)
        return np.stack([ce * np.cos(az), ce * np.sin(az), np.sin(el)], axis=-1).reshape(-1, 3)

    def scan(self, scene: Scene, pose: np.ndarray, stamp: float = 0.0) -> SimCloud:
        """One sweep from `pose` (4x4 sensor-to-world) as a world-frame SimCloud (misses and
        returns outside [min_range, max_range] are dropped). The sweep is instantaneous."""
        return _scan(scene, self.directions(), pose, self.min_range, self.max_range, stamp)


@dataclass(frozen=True)
class DepthCamera:
    """Pinhole depth camera, `width` x `height` pixels, horizontal field of view in degrees,
    square pixels, principal point at the image centre. Looks along +x of its body frame.

    baseline: metres from the camera to a structured-light projector on its right (body -y),
    as on a Kinect; points the projector cannot light are lost (0: no projector shadow)."""

    width: int = 640
    height: int = 480
    hfov_deg: float = 70.0
    min_range: float = 0.2
    max_range: float = 10.0
    rate: float = 30.0
    baseline: float = 0.0

    @classmethod
    def preset(cls, name: str) -> DepthCamera:
        """`d435` (848 x 480, 87 deg hfov, 30 Hz), `vga` (640 x 480, 70 deg) or `kinect`
        (Kinect v1: 640 x 480, focal 525 px, 0.45-4.5 m, projector 7.5 cm to the side)."""
        presets = {
            "d435": cls(848, 480, 87.0, 0.2, 10.0, 30.0),
            "vga": cls(),
            "kinect": cls(
                640, 480, float(np.degrees(2 * np.arctan(320 / 525))), 0.45, 4.5, 30.0, 0.075
            ),
        }
        if name not in presets:
            raise ValueError(f"unknown camera preset {name!r} (expected {', '.join(presets)})")
        return presets[name]

    @property
    def focal_px(self) -> float:
        """Focal length in pixels."""
        return float((self.width / 2.0) / np.tan(np.radians(self.hfov_deg) / 2.0))

    def directions(self) -> np.ndarray:
        """(height * width, 3) float64 unit rays in the body frame, row-major from the top-left
        pixel (read-only: computed once per camera). Max range applies along the ray (not the
        optical depth)."""
        return _camera_rays(self)

    def scan(
        self, scene: Scene, pose: np.ndarray, stamp: float = 0.0, organized: bool = False
    ) -> SimCloud:
        """One depth image from `pose` (4x4 body-to-world) as a world-frame SimCloud;
        `organized` keeps one row per pixel (NaN where nothing returns), like a Kinect PCD."""
        projector = np.array([0.0, -self.baseline, 0.0]) if self.baseline > 0 else None
        shape = (self.height, self.width) if organized else None
        return _scan(
            scene, self.directions(), pose, self.min_range, self.max_range, stamp, projector, shape
        )


@functools.cache
def _camera_rays(camera: DepthCamera) -> np.ndarray:
    f = camera.focal_px
    u = np.arange(camera.width) + 0.5 - camera.width / 2.0
    v = np.arange(camera.height) + 0.5 - camera.height / 2.0
    vv, uu = np.meshgrid(v, u, indexing="ij")
    d = np.stack([np.full(uu.shape, f), -uu, -vv], axis=-1).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    d.setflags(write=False)
    return d


Sensor = Lidar | DepthCamera
