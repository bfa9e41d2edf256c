"""Sampling and scanning: counts, labels, determinism, sensors, trajectories and noise."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.errors import ConfigError
from supportnode.sim import (
    ROLE_OBJECT,
    ROLE_OUTLIER,
    ROLE_STRUCTURE,
    ROLE_SURFACE,
    DepthCamera,
    Lidar,
    NoiseSpec,
    circle,
    line,
    load_scene,
    look_at,
    parse_noise,
    parse_scene,
    poses_for,
    sample_scene,
)
from supportnode.sim.simulate import sampled, scans

SCENE = """
primitives:
  - {kind: box, name: floor, size: [4, 4, 0.02], xyz: [0, 0, -0.01], role: surface, surface: floor}
  - {kind: box, name: top, size: [1, 0.6, 0.04], xyz: [0, 0, 0.73], role: surface, surface: table}
  - {kind: cylinder, name: stool, radius: 0.2, height: 0.5, xyz: [1.2, 0, 0.25], role: surface, surface: stool}
  - kind: group
    name: lamp
    role: object
    object: lamp
    xyz: [0.2, 0, 0.75]
    children:
      - {kind: cylinder, radius: 0.01, height: 0.3, xyz: [0, 0, 0.15]}
      - {kind: cone, radius: 0.1, height: 0.1, xyz: [0, 0, 0.35]}
  - {kind: sphere, name: ball, radius: 0.1, xyz: [-0.3, 0, 0.85], role: object, object: ball}
  - {kind: box, name: leg, size: [0.04, 0.04, 0.71], xyz: [0.4, 0.2, 0.355], role: structure}
"""


@pytest.fixture(scope="module")
def small():
    return parse_scene(SCENE)


def assert_labels_consistent(scene, cloud):
    """Roles, object ids and surface ids agree with the primitive each point came from."""
    prim = cloud.primitive
    hit = prim >= 0
    roles = np.array([p.role for p in scene.primitives])[prim[hit]]
    role = cloud.role[hit]
    assert ((roles == "object") == (role == ROLE_OBJECT)).all()
    assert ((roles == "structure") <= (role == ROLE_STRUCTURE)).all()
    assert ((role == ROLE_SURFACE) <= (roles == "surface")).all()
    obj = np.array([p.object_id for p in scene.primitives])[prim[hit]]
    assert (cloud.object[hit] == obj).all()
    surf = np.array([p.surface_id for p in scene.primitives])[prim[hit]]
    assert (cloud.surface[hit] == np.where(role == ROLE_SURFACE, surf, -1)).all()
    assert (cloud.role[~hit] == ROLE_OUTLIER).all()


def test_sample_counts_dtypes_and_labels(small):
    cloud = sample_scene(small, 100_003, seed=1)
    assert len(cloud) == 100_003 and cloud.points.shape == (100_003, 3)
    assert cloud.points.dtype == np.float32 and cloud.role.dtype == np.int8
    assert cloud.primitive.dtype == cloud.object.dtype == cloud.surface.dtype == np.int32
    assert np.array_equal(cloud.sensor_pose, np.eye(4))
    assert_labels_consistent(small, cloud)
    # Both lamp parts share object id 0; the ball is object 1.
    lamp = np.unique(cloud.primitive[cloud.object == 0])
    assert len(lamp) == 2 and set(np.unique(cloud.object)) == {-1, 0, 1}


def test_surface_points_only_on_top_faces(small):
    cloud = sample_scene(small, 100_000, seed=2)
    tops = {0: 0.0, 1: 0.75, 2: 0.5}  # surface id -> top height
    for sid, z in tops.items():
        pts = cloud.points[cloud.surface == sid]
        assert len(pts) > 100 and np.allclose(pts[:, 2], z, atol=1e-6)
    # Sides and bottoms of surface primitives are structure with surface id -1.
    surface_prims = [p.index for p in small.primitives if p.role == "surface"]
    rest = np.isin(cloud.primitive, surface_prims) & (cloud.role != ROLE_SURFACE)
    assert rest.sum() > 100 and (cloud.role[rest] == ROLE_STRUCTURE).all()
    assert (cloud.surface[rest] == -1).all()
    # Area proportions: the table top is 0.6 m^2 of the sampled area (faces turned to the
    # ground are not sampled).
    areas = sum(f.area for p in small.primitives for f in p.shape.faces() if not f.bottom)
    share = (cloud.surface == 1).mean()
    assert share == pytest.approx(0.6 / areas, rel=0.05)


def test_bottoms_left_out_unless_asked(small):
    def on_slab_underside(cloud):
        z = cloud.points[:, 2]
        return int((z <= z.min() + 1e-6).sum())

    assert on_slab_underside(sample_scene(small, 50_000, seed=2)) <= 2
    assert on_slab_underside(sample_scene(small, 50_000, seed=2, include_bottoms=True)) > 500


def test_sampling_is_deterministic(small):
    a, b, c = (sample_scene(small, 20_000, seed=s) for s in (7, 7, 8))
    for key in ("points", "role", "primitive", "object", "surface"):
        assert np.array_equal(getattr(a, key), getattr(b, key))
    assert not np.array_equal(a.points, c.points)


def test_sampling_in_chunks_keeps_exact_count(small, monkeypatch):
    import supportnode.sim.sensors as sensors

    monkeypatch.setattr(sensors, "_CHUNK", 1000)
    cloud = sample_scene(small, 54_321, seed=0)
    assert len(cloud) == 54_321 and np.isfinite(cloud.points).all()
    assert_labels_consistent(small, cloud)
    assert len(sample_scene(small, 0, seed=0)) == 0


def test_lidar_presets_and_directions():
    vlp = Lidar.preset("vlp16")
    os128 = Lidar.preset("os128")
    assert (vlp.beams, vlp.columns, vlp.rate) == (16, 1800, 10.0)
    assert (os128.beams, os128.columns, os128.fov_min_deg, os128.fov_max_deg) == (
        128,
        1024,
        -22.5,
        22.5,
    )
    d = os128.directions()
    assert d.shape == (128 * 1024, 3) and np.allclose(np.linalg.norm(d, axis=1), 1)
    el = np.degrees(np.arcsin(d[:, 2]))
    assert el.min() == pytest.approx(-22.5) and el.max() == pytest.approx(22.5)
    with pytest.raises(ValueError):
        Lidar.preset("hdl64")


def test_lidar_scan_labels_ranges_and_occlusion(small):
    lidar = Lidar(beams=32, fov_min_deg=-30, fov_max_deg=10, columns=720, min_range=0.3)
    pose = look_at([-1.5, -1.0, 1.2], [0, 0, 0.7], level=True)
    cloud = lidar.scan(small, pose, stamp=0.5)
    assert len(cloud) > 1000 and cloud.stamp == 0.5
    assert_labels_consistent(small, cloud)
    dist = np.linalg.norm(cloud.points - pose[:3, 3], axis=1)
    assert dist.min() >= 0.3 - 1e-6 and dist.max() <= lidar.max_range
    # Seen from above, only top faces are surface points, at the top's height.
    table = cloud.points[cloud.surface == 1]
    assert len(table) > 20 and np.allclose(table[:, 2], 0.75, atol=1e-5)
    # Sensor frame round trip.
    back = cloud.to_frame("sensor").to_frame("world")
    assert np.allclose(back.points, cloud.points, atol=1e-5)


def test_depth_camera_hits_what_it_looks_at(small):
    cam = DepthCamera(width=64, height=48, hfov_deg=40)
    pose = look_at([0.0, -1.0, 2.5], [0.0, 0.0, 0.75])
    d = cam.directions()
    assert d.shape == (64 * 48, 3)
    assert np.allclose(d.mean(axis=0) / np.linalg.norm(d.mean(axis=0)), [1, 0, 0], atol=1e-9)
    # Row-major from the top-left pixel: first ray goes left (+y) and up (+z) in the body frame.
    assert d[0, 1] > 0 and d[0, 2] > 0
    cloud = cam.scan(small, pose)
    assert len(cloud) == 64 * 48  # every pixel sees the table, its objects or the floor
    assert (cloud.surface == 1).mean() > 0.1
    assert_labels_consistent(small, cloud)
    # Looking straight down, the floor under the table top is hidden (occlusion).
    down = cam.scan(small, look_at([0.0, 0.0, 3.0], [0.0, 0.0, 0.0]))
    under = (np.abs(down.points[:, 0]) < 0.45) & (np.abs(down.points[:, 1]) < 0.25)
    assert under.sum() > 100 and not (under & (down.surface == 0)).any()
    assert np.allclose(down.points[down.surface == 1][:, 2], 0.75, atol=1e-5)


def test_trajectories():
    poses = circle([0, 0, 1.0], 2.0, 4, target=[0, 0, 0.5], level=True)
    assert poses.shape == (4, 4, 4)
    assert np.allclose(poses[:, :3, 3], [[2, 0, 1], [0, 2, 1], [-2, 0, 1], [0, -2, 1]], atol=1e-12)
    for p in poses:  # rotation, level, looking at the centre
        assert np.allclose(p[:3, :3] @ p[:3, :3].T, np.eye(3))
        assert np.allclose(p[:3, 2], [0, 0, 1])
        assert np.allclose(p[:3, 0], -p[:3, 3] * [1, 1, 0] / 2)
    tilted = look_at([0, -2, 2], [0, 0, 0])
    assert np.allclose(tilted[:3, 0], [0, 1 / np.sqrt(2), -1 / np.sqrt(2)])
    assert tilted[2, 2] > 0 and np.isclose(np.linalg.det(tilted[:3, :3]), 1)
    seg = line([0, 0, 1], [2, 0, 1], 3)
    assert np.allclose(seg[:, :3, 3], [[0, 0, 1], [1, 0, 1], [2, 0, 1]])
    assert poses_for(load_scene("shelf"), 5).shape == (5, 4, 4)


def test_scan_sequence_stamps_frames_and_determinism(small):
    lidar = Lidar(beams=8, columns=360, fov_min_deg=-25, fov_max_deg=5)
    poses = circle([0, 0, 1.2], 1.5, 3)
    noise = NoiseSpec(range=0.01, outliers=0.02)
    a = scans(small, lidar, poses, seed=3, noise=noise)
    b = scans(small, lidar, poses, seed=3, noise=noise)
    c = scans(small, lidar, poses, seed=4, noise=noise)
    assert [f.stamp for f in a] == pytest.approx([0.0, 0.1, 0.2])
    assert all(np.array_equal(x.points, y.points) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0].points, c[0].points)
    s = scans(small, lidar, poses, seed=3, noise=noise, frame="sensor")
    assert s[1].frame == "sensor" and np.allclose(s[1].sensor_pose, poses[1])
    assert np.allclose(s[1].to_frame("world").points, a[1].points, atol=1e-4)


def test_parse_noise():
    spec = parse_noise(["uniform:0.05", "range:0.01", "outliers:0.01", "tilt:2,-3"])
    assert spec == NoiseSpec(uniform=0.05, range=0.01, outliers=0.01, tilt=(2.0, -3.0))
    for bad in ["uniform", "fog:1", "range:-1", "outliers:2", "tilt:1", "gauss:x", "uniform:nan"]:
        with pytest.raises(ConfigError, match="noise"):
            parse_noise([bad])


def test_uniform_noise_and_outliers(small):
    clean = sampled(small, 20_000, seed=5)
    noisy = sampled(small, 20_000, seed=5, noise=NoiseSpec(uniform=0.05, outliers=0.01))
    assert len(noisy) == 20_200
    moved = noisy.points[:20_000] - clean.points
    assert (moved >= -1e-6).all() and (moved <= 0.05 + 1e-6).all() and moved.std() > 0.01
    out = noisy.role == ROLE_OUTLIER
    assert out.sum() == 200 and (noisy.primitive[out] == -1).all()
    assert (noisy.object[out] == -1).all() and (noisy.surface[out] == -1).all()
    lo, hi = small.bounds()
    assert (noisy.points[out] >= lo - 0.11).all() and (noisy.points[out] <= hi + 0.11).all()


def test_range_noise_follows_the_ray(small):
    lidar = Lidar(beams=8, columns=360, fov_min_deg=-25, fov_max_deg=5)
    pose = look_at([0, -1.5, 1.2], [0, 0, 0.7], level=True)
    clean = scans(small, lidar, pose[None])[0]
    noisy = scans(small, lidar, pose[None], noise=NoiseSpec(range=0.02))[0]
    a = clean.points - pose[:3, 3]
    b = noisy.points - pose[:3, 3]
    cross = np.linalg.norm(np.cross(a, b), axis=1) / np.linalg.norm(a, axis=1)
    assert cross.max() < 1e-4  # same direction
    dr = np.linalg.norm(b, axis=1) - np.linalg.norm(a, axis=1)
    assert dr.std() == pytest.approx(0.02, rel=0.15)


def test_tilt_is_recoverable(small):
    clean = sampled(small, 5000, seed=0)
    tilted = sampled(small, 5000, seed=0, noise=NoiseSpec(tilt=(3.0, -2.0)))
    r = tilted.tilt_rotation
    assert not np.allclose(r, np.eye(3))
    assert np.allclose(tilted.points @ r, clean.points, atol=1e-5)  # R^T p per row
    # The floor normal is tilted by the combined angle.
    angle = np.degrees(np.arccos(r[2, 2]))
    assert angle == pytest.approx(
        np.degrees(np.arccos(np.cos(np.radians(3)) * np.cos(np.radians(2))))
    )
