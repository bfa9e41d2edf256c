"""The depth camera as a Kinect: organised scans with NaN holes, the projector's shadow, axial
noise growing with range squared, disparity steps, lost grazing returns, optical frame."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.errors import ConfigError
from supportnode.sim import ROLE_SURFACE, DepthCamera, Lidar, look_at, parse_noise, parse_scene
from supportnode.sim.cloud import ROLE_NONE
from supportnode.sim.depth_noise import DARK_LOSS, DISPARITY_STEP, KINECT_BASELINE, kinect_noise
from supportnode.sim.files import read_sim_npz, write_sim_cloud
from supportnode.sim.simulate import sampled, scans

TABLE_TOP = 0.75

TABLE = """
primitives:
  - {kind: box, name: floor, size: [4, 4, 0.02], xyz: [0, 0, -0.01], role: surface, surface: floor}
  - {kind: box, name: top, size: [1.6, 1.0, 0.04], xyz: [0, 0, 0.73], role: surface, surface: table}
  - {kind: box, name: box, size: [0.2, 0.15, 0.1], xyz: [0, 0, 0.8], role: object, object: box}
"""
WALL = """
primitives:
  - {kind: box, name: wall, size: [0.02, 8, 8], xyz: [0, 0, 0], role: surface, surface: wall}
"""
SMALL = DepthCamera(160, 120, 60.0, 0.3, 6.0, 30.0)


@pytest.fixture(scope="module")
def table():
    return parse_scene(TABLE)


def oblique(distance: float) -> np.ndarray:
    el = np.radians(50.0)
    return look_at([-distance * np.cos(el), 0.0, 0.75 + distance * np.sin(el)], [0, 0, 0.75])


def test_organised_scan_keeps_a_nan_row_per_empty_pixel(table):
    pose = look_at([-1.5, 0.0, 1.0], [0.0, 0.0, 1.0])  # level: the upper half sees nothing
    org = SMALL.scan(table, pose, organized=True)
    assert len(org) == 160 * 120 and org.image_shape == (120, 160)
    empty = ~np.isfinite(org.points).all(axis=1)
    assert 0.2 < empty.mean() < 0.9
    assert (org.role[empty] == ROLE_NONE).all()
    assert (org.object[empty] == -1).all() and (org.primitive[empty] == -1).all()
    flat = SMALL.scan(table, pose)
    assert flat.image_shape is None
    assert np.array_equal(org.points[~empty], flat.points)
    assert np.array_equal(org.surface[~empty], flat.surface)
    assert org.select(~empty).image_shape is None


def test_projector_shadow_beside_an_object(table):
    pose = oblique(1.0)
    plain = SMALL.scan(table, pose, organized=True)
    lit = DepthCamera(160, 120, 60.0, 0.3, 6.0, 30.0, baseline=0.075).scan(
        table, pose, organized=True
    )
    lost = np.isfinite(plain.points[:, 0]) & ~np.isfinite(lit.points[:, 0])
    near = np.all(np.abs(plain.points[:, :2]) < 0.3, axis=1)  # the table around the box
    lost &= near
    assert lost.sum() > 10
    # What the shadow hides is table beside the box, on the side away from the projector
    # (the projector sits to the camera's right, body -y; the shadow falls to the left, +y).
    assert (plain.surface[lost] == 1).all()
    box_y = plain.points[plain.object == 0, 1]
    assert (plain.points[lost, 1] > np.median(box_y)).mean() > 0.9


def wall_scan(distance: float, seed: int = 0, incidence_deg: float = 0.0):
    """An organised Kinect scan of a wall `distance` m ahead, turned by `incidence_deg`."""
    scene = parse_scene(
        WALL.replace("xyz: [0, 0, 0]", f"xyz: [0, 0, 0], rpy: [0, 0, {incidence_deg}]")
    )
    pose = look_at([-distance, 0.0, 0.0], [0.0, 0.0, 0.0])
    cam = DepthCamera.preset("kinect")
    clean = cam.scan(scene, pose, organized=True)
    noisy = kinect_noise(clean, scene, cam, np.random.default_rng(seed))
    return clean, noisy, pose, cam


def test_axial_noise_grows_with_range_squared_and_depth_is_quantised():
    spread = {}
    for distance in (0.6, 1.0, 1.5):
        clean, noisy, pose, cam = wall_scan(distance)
        ok = np.isfinite(noisy.points[:, 0])
        depth = (noisy.points[ok].astype(np.float64) - pose[:3, 3]) @ pose[:3, 0]
        true = (clean.points[ok].astype(np.float64) - pose[:3, 3]) @ pose[:3, 0]
        err = depth - true
        # Nguyen et al.'s sigma plus the disparity step's uniform error (step^2 / 12).
        sigma = 0.0012 + 0.0019 * (distance - 0.4) ** 2
        step = distance**2 * DISPARITY_STEP / (cam.focal_px * KINECT_BASELINE)
        assert err.std() == pytest.approx(np.sqrt(sigma**2 + step**2 / 12), rel=0.15)
        assert abs(err.mean()) < 0.2 * sigma
        # Measured depths sit on disparity steps: f b / z is a multiple of 1/8 pixel.
        levels = cam.focal_px * KINECT_BASELINE / depth / DISPARITY_STEP
        assert np.allclose(levels, np.round(levels), atol=2e-3)
        spread[distance] = err.std()
    assert spread[0.6] < spread[1.0] < spread[1.5]
    assert spread[1.5] > 2.0 * spread[0.6]


def test_holes_at_grazing_angles_and_on_dark_pixels():
    _, facing, _, _ = wall_scan(1.0)
    lost = ~np.isfinite(facing.points[:, 0])
    assert 0.5 * DARK_LOSS < lost.mean() < 3 * DARK_LOSS  # scattered dark pixels only
    assert (facing.role[lost] == ROLE_NONE).all() and (facing.surface[lost] == -1).all()
    clean_steep, steep, _, _ = wall_scan(1.0, incidence_deg=82.0)
    seen = np.isfinite(clean_steep.points[:, 0])
    assert (~np.isfinite(steep.points[seen, 0])).mean() > 0.6


def test_kinect_noise_is_seeded_and_labels_follow_the_measured_point(table):
    cam = DepthCamera.preset("kinect")
    pose = oblique(1.0)
    a, b, c = (
        scans(table, cam, pose[None], seed=s, noise=parse_noise(["kinect"]), organized=True)[0]
        for s in (1, 1, 2)
    )
    assert np.array_equal(a.points, b.points, equal_nan=True)
    assert not np.array_equal(a.points, c.points, equal_nan=True)
    ok = np.isfinite(a.points[:, 0])
    # Table points stay within a few sigma of the table top; the box's points above it.
    top = ok & (a.surface == 1)
    assert np.abs(a.points[top, 2] - 0.75).max() < 0.03
    assert (a.role[top] == ROLE_SURFACE).all()
    assert np.median(a.points[ok & (a.object == 0), 2]) > 0.78
    # Unorganised: the same points without the holes.
    flat = scans(table, cam, pose[None], seed=1, noise=parse_noise(["kinect"]))[0]
    assert flat.image_shape is None and np.array_equal(flat.points, a.points[ok])


def test_kinect_spec_and_its_errors(table):
    assert parse_noise(["kinect"]).kinect == 1.0
    assert parse_noise(["kinect:2.5"]).kinect == 2.5
    with pytest.raises(ConfigError, match="non-negative"):
        parse_noise(["kinect:-1"])
    with pytest.raises(ConfigError, match="depth camera"):
        scans(table, Lidar(beams=4, columns=36), oblique(1.0)[None], noise=parse_noise(["kinect"]))
    with pytest.raises(ConfigError, match="depth camera"):
        sampled(table, 100, noise=parse_noise(["kinect"]))
    with pytest.raises(ValueError, match="organised"):
        kinect_noise(SMALL.scan(table, oblique(1.0)), table, SMALL, np.random.default_rng(0))


def test_optical_frame_and_npz_round_trip(table, tmp_path):
    pose = oblique(1.0)
    org = SMALL.scan(table, pose, organized=True)
    opt = org.to_frame("optical")
    ok = np.isfinite(opt.points[:, 0])
    assert (opt.points[ok, 2] > 0).all()  # z forward
    # Row-major from the top-left: x grows to the right along a row, y downwards.
    img = opt.points.reshape(120, 160, 3)
    assert img[60, 100, 0] > img[60, 60, 0] and img[90, 80, 1] > img[30, 80, 1]
    back = opt.to_frame("world")
    assert np.allclose(back.points[ok], org.points[ok], atol=1e-5)
    assert np.allclose(
        opt.to_frame("sensor").points[ok], org.to_frame("sensor").points[ok], atol=1e-5
    )
    path = write_sim_cloud(tmp_path / "k.npz", opt)
    again = read_sim_npz(path)
    assert again.image_shape == (120, 160) and again.frame == "optical"
    assert np.array_equal(again.points, opt.points, equal_nan=True)


def test_lateral_noise_frays_edges_only(table):
    cam = DepthCamera.preset("kinect")
    pose = oblique(1.0)
    clean = cam.scan(table, pose, organized=True)
    noisy = kinect_noise(clean, table, cam, np.random.default_rng(5))
    both = np.isfinite(clean.points[:, 0]) & np.isfinite(noisy.points[:, 0])
    moved = both & (clean.primitive != noisy.primitive)  # a neighbour's surface measured
    assert moved.sum() > 50
    # On the open table the error off the plane is the axial noise and the disparity step
    # alone, seen along the normal: no lateral jitter along the slope of the table.
    ray = clean.points.astype(np.float64) - pose[:3, 3]
    depth = ray @ pose[:3, 0]
    # A depth error dz moves the point along its ray by dz |ray| / depth, off the table by
    # that times the cosine of the incidence: |ray_z| / |ray|.
    to_normal = np.abs(ray[:, 2]) / depth
    sigma = 0.0012 + 0.0019 * (depth - 0.4) ** 2
    step = depth**2 * DISPARITY_STEP / (cam.focal_px * KINECT_BASELINE)
    expected = to_normal * np.sqrt(sigma**2 + step**2 / 12)
    x, y = np.abs(clean.points[:, 0]), np.abs(clean.points[:, 1])
    open_table = both & (clean.surface == 1) & (noisy.surface == 1) & (x > 0.2) & (x < 0.7)
    open_table &= y < 0.4
    err = (noisy.points[open_table, 2] - TABLE_TOP) / expected[open_table]
    assert np.std(err) == pytest.approx(1.0, abs=0.1)
    # Every measurement lies on its own pixel's ray.
    rays = cam.directions() @ pose[:3, :3].T
    offset = noisy.points[both].astype(np.float64) - pose[:3, 3]
    along = np.einsum("ij,ij->i", offset, rays[both])
    assert np.allclose(offset, along[:, None] * rays[both], atol=1e-4)
