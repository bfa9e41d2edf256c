"""Gravity alignment on synthetic rooms (tilted, any yaw), camera-frame clouds and failures."""

from __future__ import annotations

import glob
import os

import numpy as np
import pytest

from supportnode.errors import AlignmentError
from supportnode.geometry.gravity import apply_rotation, estimate_gravity, rotation_to_z
from supportnode.params import GravityParams

REAL_DIR = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "real_scans")


def _box(rng: np.random.Generator, lo, hi, density: float, top_only: bool = False) -> np.ndarray:
    """Points on the faces of an axis-aligned box, `density` points per m^2."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    out = []
    for ax in range(3):
        for side in (0, 1):
            if top_only and not (ax == 2 and side == 1):
                continue
            o = [i for i in range(3) if i != ax]
            n = rng.poisson((hi[o[0]] - lo[o[0]]) * (hi[o[1]] - lo[o[1]]) * density)
            p = np.empty((n, 3))
            p[:, ax] = hi[ax] if side else lo[ax]
            for i in o:
                p[:, i] = rng.uniform(lo[i], hi[i], n)
            out.append(p)
    return np.concatenate(out)


def room(rng: np.random.Generator, density: float = 2500.0, noise: float = 0.005) -> np.ndarray:
    """Floor 6x6 m at z=0, a table (top 0.72-0.76 m, four legs), boxes on it and on the
    floor, two walls; about 140k points, z up."""
    parts = [_box(rng, [-3, -3, -0.05], [3, 3, 0], density, top_only=True)]
    parts.append(_box(rng, [-0.6, -0.4, 0.72], [0.6, 0.4, 0.76], density))
    for x in (-0.55, 0.5):
        for y in (-0.35, 0.3):
            parts.append(_box(rng, [x, y, 0], [x + 0.05, y + 0.05, 0.72], density))
    for lo, hi in (
        ([0.1, 0, 0.76], [0.3, 0.15, 0.96]),
        ([-0.4, -0.2, 0.76], [-0.25, -0.05, 0.86]),
        ([1.5, 1, 0], [1.9, 1.5, 0.5]),
        ([-2, 1, 0], [-1.6, 1.3, 0.3]),
    ):
        parts.append(_box(rng, lo, hi, density))
    parts.append(_box(rng, [3, -3, 0], [3.1, 3, 2.5], density / 4))
    parts.append(_box(rng, [-3, 3, 0], [3, 3.1, 2.5], density / 4))
    p = np.concatenate(parts)
    return p + rng.normal(0.0, noise, p.shape)


def rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll), degrees."""
    r, p, y = np.radians([roll, pitch, yaw])
    rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(
        np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))
    )


SENSOR = np.array([0.5, -1.0, 1.5])  # a sensor 1.5 m above the floor, beside the table


@pytest.mark.parametrize("case", range(20))
def test_tilted_room_any_yaw(case: int) -> None:
    rng = np.random.default_rng(100 + case)
    pts = room(rng, density=700.0)  # ~40k points: keeps the sweep fast
    roll, pitch = rng.uniform(-45, 45, 2)
    rot = rpy(roll, pitch, rng.uniform(0, 360))
    cloud = apply_rotation(pts - SENSOR, rot)  # sensor frame: sensor at the origin
    est = estimate_gravity(cloud)
    true_up = rot @ np.array([0.0, 0.0, 1.0])
    assert angle_deg(est.up, true_up) < 1.0
    # R @ up = +z, and the rotation is proper
    np.testing.assert_allclose(est.rotation @ est.up, [0, 0, 1], atol=1e-9)
    np.testing.assert_allclose(est.rotation @ est.rotation.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(est.rotation) == pytest.approx(1.0)
    assert est.tilt_deg == pytest.approx(angle_deg(est.up, np.array([0, 0, 1.0])))
    assert est.inliers > 1000 and est.residual_deg < 5.0


def test_rotation_is_minimal_keeps_yaw() -> None:
    up = np.array([0.3, 0.0, 1.0])
    r = rotation_to_z(up)
    np.testing.assert_allclose(r @ (up / np.linalg.norm(up)), [0, 0, 1], atol=1e-12)
    # the axis perpendicular to the tilt plane is untouched: no yaw added
    np.testing.assert_allclose(r @ [0, 1, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(rotation_to_z(np.array([0, 0, -2.0])) @ [0, 0, -1], [0, 0, 1])


def test_camera_frame_cloud_up_is_minus_y() -> None:
    """Optical frame (x right, y down, z forward), camera 1.5 m high pitched 20 deg down:
    up is -y tilted toward -z."""
    rng = np.random.default_rng(7)
    pts = room(rng, density=1500.0)
    # body (x fwd, y left, z up) -> optical (z fwd, x right, y down), pitch down 20 deg
    optical_from_body = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    body_from_world = rpy(0, 20, 30).T  # looking down 20 deg, yawed 30 deg
    rot = optical_from_body @ body_from_world
    cam = np.array([-2.5, -1.5, 1.5])
    cloud = apply_rotation(pts - cam, rot)
    cloud = cloud[cloud[:, 2] > 0.2]  # a camera sees only what is in front of it
    est = estimate_gravity(cloud)
    true_up = rot @ np.array([0.0, 0.0, 1.0])
    assert true_up[1] < -0.9 and true_up[2] < 0  # the premise: -y tilted toward -z
    assert angle_deg(est.up, true_up) < 1.0


def test_up_hint_sets_sign_and_family() -> None:
    rng = np.random.default_rng(3)
    pts = room(rng, density=1000.0)
    # Upside down and the sensor given below the floor: the hint still decides.
    est = estimate_gravity(-pts, GravityParams(up_hint=(0.0, 0.0, -1.0)))
    assert angle_deg(est.up, np.array([0, 0, -1.0])) < 1.0
    with pytest.raises(AlignmentError, match="up_hint"):
        estimate_gravity(
            _box(rng, [0, 0, 0], [0.01, 3, 3], 3000.0, top_only=False),
            GravityParams(up_hint=(0.0, 0.0, 1.0)),
        )


@pytest.mark.parametrize("kind", ["sphere", "noise", "wall"])
def test_no_horizontal_surface_raises(kind: str) -> None:
    rng = np.random.default_rng(5)
    if kind == "sphere":
        v = rng.normal(size=(50000, 3))
        pts = 2.0 * v / np.linalg.norm(v, axis=1, keepdims=True)
    elif kind == "noise":
        pts = rng.uniform(-2, 2, (50000, 3))
    else:  # one bare wall 2 m ahead of the sensor, nothing else
        pts = np.column_stack(
            [np.full(50000, 2.0), rng.uniform(-2, 2, 50000), rng.uniform(-1, 1.5, 50000)]
        )
    with pytest.raises(AlignmentError, match="no horizontal surface in view"):
        estimate_gravity(pts)


def test_nan_rows_are_ignored() -> None:
    rng = np.random.default_rng(11)
    pts = room(rng, density=800.0) - SENSOR
    pts[::7] = np.nan  # organised clouds mark missing pixels with NaN
    est = estimate_gravity(pts)
    assert angle_deg(est.up, np.array([0, 0, 1.0])) < 1.0


def _sim_available() -> bool:
    try:
        from supportnode.sim.scene import bundled_scenes
    except ImportError:
        return False
    return len(bundled_scenes()) > 0


@pytest.mark.skipif(not _sim_available(), reason="simulator scenes not available")
@pytest.mark.parametrize("tilt", [(10.0, -5.0), (-30.0, 25.0)])
def test_sim_scenes_tilted(tilt: tuple[float, float]) -> None:
    from supportnode.sim.noise import apply_tilt
    from supportnode.sim.scene import bundled_scenes, load_scene
    from supportnode.sim.sensors import sample_scene

    for name in bundled_scenes():
        cloud = apply_tilt(sample_scene(load_scene(name), 60_000, seed=1), *tilt)
        est = estimate_gravity(cloud.points.astype(np.float64), sensor_origin=None)
        true_up = cloud.tilt_rotation @ np.array([0.0, 0.0, 1.0])
        assert angle_deg(est.up, true_up) < 1.0, name


@pytest.mark.real
@pytest.mark.skipif(not os.path.isdir(REAL_DIR), reason="../shared/real_scans absent")
def test_real_camera_scans_up_is_near_minus_y() -> None:
    clouds = pytest.importorskip("supportnode.io.clouds")
    files = sorted(glob.glob(os.path.join(REAL_DIR, "*.pcd")))
    if not files:
        pytest.skip("no PCD files in real_scans")
    for path in files:
        if "sick" in path:
            continue  # millimetres; looks steeply down, covered by the bench
        pts = clouds.read_cloud(path).points.astype(np.float64)
        est = estimate_gravity(pts, GravityParams(up_hint=(0.0, -1.0, 0.0)))
        # camera held upright: up within 60 deg of -y, never pointing into the scene (+z)
        assert est.up[1] < -0.5 and est.up[2] < 0.1, (path, est.up)
        assert est.residual_deg < 8.0
